#include "pipeline/distributed/run_distributed.hpp"
#include "pipeline/write/brick_reorder.hpp"
#include "pipeline/write/label_order.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_writer.hpp"
#include "io/point_format.hpp"
#include "pipeline/util/disk_meter.hpp"
#include "pipeline/util/fault.hpp"
#include "pipeline/write/frame_cutter.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/distributed/point_sort_distributed.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/util/resident_memory.hpp"
#include "pipeline/distributed/rank_cost.hpp"
#include "pipeline/distributed/rank_records.hpp"
#include "pipeline/run/run_internal.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/run/stage_index.hpp"
#include "pipeline/run/stage_sort.hpp"
#include "pipeline/run/stage_triangulate.hpp"
#include "pipeline/run/stage_write.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/files/work_dir.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <sys/stat.h>

#include <omp.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tetstream::pipeline {

using nlohmann::json;

namespace {

std::string rank_prefix(int rank) { return "rank-" + std::to_string(rank); }
std::string fragment_name(int rank) { return rank_prefix(rank) + ".tets"; }
std::string progress_file(const std::string& dir, int rank) { return dir + "/" + rank_prefix(rank) + ".progress"; }

// The work files of ranks 1 and up in the job's checkpoint directory (their records,
// pending frames, fragments, progress counts, sort runs), by the names work_dir.hpp
// owns; never a directory, never through a link (unlink removes the link itself).
void remove_other_ranks_files(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (work_file_rank(name) >= 1 && !std::filesystem::is_directory(entry.symlink_status())) names.push_back(name);
  }
  for (const std::string& name : names) remove_file(dir + "/" + name);
}

// One rank's part of the job, from the sort to its frames written. Rank 0 owns the
// output's claim, the work directory and the sort; every collective step is inside
// together(), so the ranks stop at the same step when one fails.
class RankJob {
 public:
  // `dir`: the job's work directory (rank 0's checkpoint, or a TempDir); `checkpoint`:
  // this rank's (null: not resumable), whose state is `state`.
  RankJob(const RunOptions& options, Communicator& comm, const std::string& dir, const io::OutputClaim* claim,
          Checkpoint* checkpoint, json& state)
      : options_(options),
        comm_(comm),
        dir_(dir),
        claim_(claim),
        checkpoint_(checkpoint),
        state_(state),
        threads_(options.threads > 0 ? options.threads : omp_get_max_threads()),
        budget_(options.memory_bytes, 0, threads_, omp_get_num_procs()) {}

  RunSummary run() {
    const bool root = comm_.rank() == 0;
    RunSummary& summary = summary_;
    DiskMeter disk(dir_, root ? options_.output + ".partial" : "");
    const StageContext context{options_, dir_, checkpoint_, state_, root ? &disk : nullptr};
    summary.resumed = state_.contains("sort") || state_.contains("sorted") || state_.contains("output");

    // ---- sort ----
    std::optional<SortStage> sort;
    const std::string sorted_text = comm_.broadcast(sort_step(context, sort), 0);
    const SortedPoints sorted = root ? sort->result() : sorted_from_json(json::parse(sorted_text));
    summary.input_points = sorted.input_count;
    summary.points = sorted.count;
    summary.duplicates = sorted.duplicates;
    summary.axis = sorted.axis;

    // ---- index and plan, on every rank ----
    IndexStage index(sorted, threads_);
    std::optional<TriangulatePlan> plan;
    RunSummary::Rank mine;
    index_step(index, plan, mine);
    summary.hull_vertices = index.view().hull_points.size();

    // ---- triangulate this rank's blocks of labels; its frames to the output (rank
    // 0) or to its fragment ----
    // Whether rank 0 prints progress (the others are quiet, and share their counts).
    const bool job_progress = comm_.broadcast(options_.progress ? "yes" : "", 0) == "yes";
    // Whole frame blocks, and with --labels bricks whole bricks (both powers of two: the
    // larger is a multiple of the smaller), so each rank's tets are those of its bricks.
    const std::uint64_t block = std::max(frame_block_labels(budget_.frame_tets()),
                                         options_.brick_labels ? brick_labels(sorted.count) : std::uint64_t(1));
    assign_labels(index, sorted.count, block, mine);
    // A rank whose fragment an earlier process finished (the job failed before it
    // succeeded) has nothing left to triangulate: its frames are checked as it places
    // them.
    const std::string fragment = context.dir + "/" + fragment_name(comm_.rank());
    const bool fragment_done = !root && state_.contains("output") && state_["output"].value("finishing", false) &&
                               std::filesystem::exists(fragment) && !std::filesystem::exists(fragment + ".partial");
    WriteStage write(context, sorted, index.view(), plan->shares, root ? claim_ : nullptr);
    if (root) write.defer_points_order();  // the other ranks read the points until they are done
    std::optional<TriangulateStage> triangulate;
    const WrittenWork work =
        triangulate_step(sorted, index, *plan, write, triangulate, fragment, fragment_done, job_progress, mine);
    mine.tets = work.stats.tets;

    const std::vector<std::string> ranks = place_step(write, fragment, sorted, work, disk, mine);
    fold_summary(ranks, mine, triangulate);
    return summary;
  }

 private:
  // Which labels this rank triangulates: a contiguous run of blocks of about a K-th of
  // the job's expected cost (rank_cost.hpp), rank 0's from where its frames end.
  void assign_labels(const IndexStage& index, std::uint64_t count, std::uint64_t block, RunSummary::Rank& mine) {
    const bool root = comm_.rank() == 0;
    const int size = comm_.size();
    // Rank 0's frames so far (an earlier process's record, maybe on another number of
    // ranks) stay in its range.
    std::string written;
    if (root)
      written = std::to_string(state_.contains("output") ? state_["output"].at("next_label").get<std::uint64_t>() : 0);
    const std::uint64_t rank0_done = std::stoull(comm_.broadcast(written, 0));
    const std::vector<std::uint64_t> costs = block_costs(index, count, block);
    const std::vector<std::uint64_t> bounds = rank_label_bounds(count, block, size, rank0_done, costs);
    {
      const auto cost_of = [&](std::uint64_t a, std::uint64_t b) {  // of labels [a, b), whole blocks
        std::uint64_t c = 0;
        for (std::uint64_t i = a / block; i < (b + block - 1) / block; ++i) c += costs[std::size_t(i)];
        return double(c);
      };
      const double total = cost_of(0, count);
      mine.expected_cost_share =
          total > 0 ? cost_of(bounds[std::size_t(comm_.rank())], bounds[std::size_t(comm_.rank()) + 1]) / total : 0;
    }
    mine.first_label = bounds[std::size_t(comm_.rank())];
    mine.end_label = bounds[std::size_t(comm_.rank()) + 1];
    if (root)
      spdlog::info("{} ranks: blocks of {} labels, rank 0 from label {} to {}", size, block, mine.first_label,
                   mine.end_label);
  }

  // Triangulates this rank's labels: its frames go to the output (rank 0) or to its
  // fragment. A rank whose fragment an earlier process finished only reads its record.
  WrittenWork triangulate_step(const SortedPoints& sorted, IndexStage& index, const TriangulatePlan& plan,
                               WriteStage& write, std::optional<TriangulateStage>& triangulate,
                               const std::string& fragment, bool fragment_done, bool job_progress,
                               RunSummary::Rank& mine) {
    const bool root = comm_.rank() == 0;
    const int size = comm_.size();
    WrittenWork work;
    together(comm_, [&] {
      if (fragment_done) {
        work = counters_from(state_["output"].at("counters"));
        mine.segments = state_["output"].at("segments").get<std::uint64_t>();
        return;
      }
      if (!root) write.write_fragment(fragment, rank_prefix(comm_.rank()) + "-pending-");
      write.prepare();
      write.run();
      // From where this rank's record says its labels are written (a resumed job).
      const std::uint64_t from = std::max(mine.first_label, write.first_label());
      triangulate.emplace(options_, index, plan.zones, plan.shares.query_page_bytes, plan.shares.shared_rim_bytes,
                          threads_);
      triangulate->prepare(from, write.segments_done(), mine.end_label);
      if (job_progress) {
        // One progress line for the job, rank 0's, counting every rank's labels.
        TriangulateStage::SharedProgress shared;
        shared.total = sorted.count;
        shared.base = mine.first_label;
        if (root)
          for (int r = 1; r < size; ++r) shared.peers.push_back(progress_file(dir_, r));
        else
          shared.own = progress_file(dir_, comm_.rank());
        triangulate->share_progress(std::move(shared));
      }
      budget_.plan_triangulate(plan.shares.index_bytes, triangulate->window_bytes());
      triangulate->run(write);
      write.commit(mine.end_label);
      if (!root) write.finish();
      work = write.work();
      mine.segments = write.segments_done();
      mine.zones = triangulate->zones();
      mine.frame_bytes = write.tet_bytes();
      mine.seconds_triangulate = triangulate->seconds();
      mine.seconds_write = write.seconds();
    });
    return work;
  }

  // Places every rank's frames into the output and, on rank 0, finishes it; returns
  // the ranks' summaries (on rank 0).
  std::vector<std::string> place_step(WriteStage& write, const std::string& fragment, const SortedPoints& sorted,
                                      const WrittenWork& work, DiskMeter& disk, RunSummary::Rank& mine) {
    const bool root = comm_.rank() == 0;
    const int size = comm_.size();
    RunSummary& summary = summary_;
    // ---- place: every rank copies its own frames into the output, where the ranks
    // before it end (rank 0's own frames are there already); rank 0 then indexes them
    // and writes the index and footer. No rank's frames pass through another rank. A
    // failure here leaves rank 0's record at its own frames: --resume places them
    // again from the fragments, which stay until the job succeeds. ----
    const auto place_start = StageClock::now();
    const std::string partial = options_.output + ".partial";
    std::string where;  // rank 0: its frames' end, and the output file's identity
    std::uint64_t fragment_bytes = 0;
    together(comm_, [&] {
      if (root) {
        const std::uint64_t at = write.fragments_offset();
        struct stat st {};
        if (::lstat(partial.c_str(), &st) != 0 || !S_ISREG(st.st_mode))
          throw IoError(partial + ": the output being written is gone or not a regular file");
        where = json::array({at, std::uint64_t(st.st_dev), std::uint64_t(st.st_ino)}).dump();
      } else {
        fragment_bytes = std::filesystem::file_size(fragment);
      }
    });
    const json place = json::parse(comm_.broadcast(where, 0));
    const std::vector<std::uint64_t> sizes = comm_.all_gather(fragment_bytes);
    std::string placed;  // this rank's frames as placed, in the container index's encoding
    together(comm_, [&] {
      if (root) return;
      std::uint64_t at = place.at(0).get<std::uint64_t>();
      for (int r = 1; r < comm_.rank(); ++r) at += sizes[std::size_t(r)];
      maybe_inject_fault("place", 0);
      const std::vector<io::FrameEntry> frames = io::place_fragment(
          fragment, partial, at, sorted.count, {place.at(1).get<std::uint64_t>(), place.at(2).get<std::uint64_t>()});
      const std::vector<std::uint8_t> bytes = io::serialize_index({}, frames);
      placed.assign(bytes.begin(), bytes.end());
    });
    const std::vector<std::string> all_placed = comm_.gather(placed, 0);
    if (!root) mine.seconds_write += seconds_since(place_start);  // its frames placed
    // Up to this summary; the summaries and the last agreements add a few hundred bytes.
    mine.message_bytes = comm_.bytes_sent();
    const std::vector<std::string> ranks = comm_.gather(rank_json(mine, work).dump(), 0);
    together(comm_, [&] {
      if (!root) return;
      std::vector<io::FrameEntry> frames;
      std::uint64_t bytes = 0;
      for (int r = 1; r < size; ++r) {
        bytes += sizes[std::size_t(r)];
        const std::string& text = all_placed[std::size_t(r)];
        std::vector<io::SectionEntry> none;
        std::vector<io::FrameEntry> theirs;
        if (const std::string problem =
                io::parse_index({reinterpret_cast<const std::uint8_t*>(text.data()), text.size()}, none, theirs);
            !problem.empty())
          throw IoError("rank " + std::to_string(r) + "'s placed frames: " + problem);
        frames.insert(frames.end(), theirs.begin(), theirs.end());
      }
      write.adopt_fragments(std::move(frames), bytes);
      write.reorder_points_section();
      write.finish();
      summary.seconds_write = seconds_since(place_start);
      disk.sample();
      summary.disk_peak_bytes = std::max(disk.peak(), disk.sample());
      summary.output_bytes = write.bytes_written();
      summary.tet_bytes = write.tet_bytes();
    });
    return ranks;
  }

  // The job's summary from the ranks' (rank 0), or this rank's own.
  void fold_summary(const std::vector<std::string>& ranks, const RunSummary::Rank& mine,
                    const std::optional<TriangulateStage>& triangulate) {
    const bool root = comm_.rank() == 0;
    RunSummary& summary = summary_;
    if (root) {
      WrittenWork all;
      for (const std::string& text : ranks) {
        const json j = json::parse(text);
        summary.ranks.push_back(rank_from(j));
        const WrittenWork w = counters_from(j.at("work"));
        all.stats += w.stats;
        all.segment_labels += w.segment_labels;
        summary.segments += summary.ranks.back().segments;
        summary.zones += summary.ranks.back().zones;
        summary.seconds_index = std::max(summary.seconds_index, summary.ranks.back().seconds_index);
        summary.seconds_triangulate = std::max(summary.seconds_triangulate, summary.ranks.back().seconds_triangulate);
      }
      record_work(all, summary);
      summary.query_region_releases = triangulate ? triangulate->query_region_releases() : 0;
      summary.seconds_write += mine.seconds_write;
      summary.seconds_total = seconds_since(start_);
      summary.memory_ceiling = budget_.ceiling();
      summary.memory_shares = budget_.shares();
      summary.memory_peak_bytes = peak_resident_bytes();
    } else {
      summary.ranks.push_back(mine);
      summary.tets = mine.tets;
      summary.segments = mine.segments;
      summary.zones = mine.zones;
    }
  }

  // The sort: spread over the ranks (each reads, sorts and writes its part), or on rank
  // 0 alone for an input without a count up front (text), or as rank 0's checkpoint
  // recorded it. Returns, on rank 0, the sorted points' description for the others.
  std::string sort_step(const StageContext& context, std::optional<SortStage>& sort) {
    const bool root = comm_.rank() == 0;
    std::string how, identity;
    together(comm_, [&] {
      if (!root) return;
      sort.emplace(context, budget_, threads_, claim_);
      sort->prepare();
      how = sort->recorded() ? "recorded" : sorts_by_ranges(options_.input, options_.read) ? "ranks" : "root";
      const io::OutputPart::Identity id = io::OutputPart::identity_of(claim_->fd());
      identity = json::array({id.first, id.second}).dump();
    });
    how = comm_.broadcast(how, 0);
    if (how == "ranks") {
      DistributedSortTarget target;
      target.partial = options_.output + ".partial";
      if (root) target.header = sort->points_header();
      const json id = json::parse(comm_.broadcast(identity, 0));
      target.identity = {id.at(0).get<std::uint64_t>(), id.at(1).get<std::uint64_t>()};
      PointSortOptions sort_options;
      sort_options.memory_bytes = std::size_t(options_.memory_bytes);
      sort_options.budget = &budget_;
      sort_options.run_points = std::size_t(options_.sort_run_points);
      sort_options.progress = options_.progress;
      sort_options.on_scanned = [this](const SortProgress& p) {
        refuse_budget_before_sort(p, options_.plan_options(), threads_);
      };
      SortedPoints made;
      {
        const ScopedThreads threads(threads_);
        // This rank's runs: rank-R-points-K.run in the work directory (the sorter
        // removes them; a stopped job's are work files its directory's owner clears).
        made = sort_points_distributed(comm_, options_.input, options_.read, sort_options, dir_,
                                       rank_prefix(comm_.rank()) + "-points", target);
      }
      together(comm_, [&] {
        if (!root) return;
        sort->adopt(std::move(made));
        sort->commit();
      });
    }
    std::string sorted_text;
    together(comm_, [&] {
      if (!root) return;
      const SortedPoints& s = how == "root" ? sort->run() : sort->result();
      if (how == "root") sort->commit();
      if (s.count < 4) throw InputError(options_.input + ": fewer than 4 distinct points");
      sorted_text = sorted_json(s).dump();
      summary_.seconds_sort = seconds_since(start_);
      spdlog::info("sorted {} points ({} duplicates merged) along {} in {} runs{}, {:.1f}s", s.count, s.duplicates,
                   "xyz"[s.axis], s.runs, how == "ranks" ? " on every rank" : "", summary_.seconds_sort);
    });
    return sorted_text;
  }

  // Every block's expected cost (pipeline/rank_cost.hpp), in the units of a point:
  // rank r computes the r-th K-th of them from the shared index, rank 0 gathers them
  // and hands all of them to every rank, which then cut the same ranges.
  std::vector<std::uint64_t> block_costs(const IndexStage& index, std::uint64_t count, std::uint64_t block) {
    const std::uint64_t blocks = (count + block - 1) / block, k = std::uint64_t(comm_.size()),
                        r = std::uint64_t(comm_.rank());
    std::string mine;
    const auto start = StageClock::now();
    together(comm_, [&] {
      const std::uint64_t b0 = blocks * r / k, b1 = blocks * (r + 1) / k;
      const std::uint64_t first = std::min(count, b0 * block), last = std::min(count, b1 * block);
      double sum = 0;
      for (double c : expected_cost(*index.view().index, index.view().points, first, last, block)) {
        const std::uint64_t v = std::uint64_t(std::llround(c));
        mine.append(reinterpret_cast<const char*>(&v), sizeof v);
        sum += c;
      }
      index.release_pages();
      spdlog::debug("expected costs of {} blocks of {} labels: {:.3f} a point, {:.2f}s", b1 - b0, block,
                    last > first ? sum / double(last - first) : 0.0, seconds_since(start));
    });
    const std::vector<std::string> parts = comm_.gather(mine, 0);
    std::string all;
    for (const std::string& p : parts) all += p;
    all = comm_.broadcast(all, 0);
    std::vector<std::uint64_t> costs(all.size() / sizeof(std::uint64_t));
    std::memcpy(costs.data(), all.data(), costs.size() * sizeof(std::uint64_t));
    if (costs.size() != blocks) throw std::logic_error("block_costs: the ranks' parts do not add up");
    return costs;
  }

  // The index: each rank builds a K-th of its blocks into one file, which every rank
  // then maps (pipeline/stage_index.hpp): the build is shared, and the index is held by
  // the page cache, not once a rank. Then the zone plan.
  void index_step(IndexStage& index, std::optional<TriangulatePlan>& plan, RunSummary::Rank& mine) {
    const int size = comm_.size();
    const std::string path = dir_ + "/index.shared";
    const auto start = StageClock::now();
    std::uint64_t my_nodes = 0;
    together(comm_, [&] {
      index.prepare();
      my_nodes = index.build_shared_part(comm_.rank(), size);
    });
    const std::vector<std::uint64_t> nodes = comm_.all_gather(my_nodes);
    std::uint64_t total_nodes = 0, first_node = 0;
    for (int r = 0; r < size; ++r) {
      if (r < comm_.rank()) first_node += nodes[std::size_t(r)];
      total_nodes += nodes[std::size_t(r)];
    }
    together(comm_, [&] {
      if (comm_.rank() == 0) index.create_shared_file(path, total_nodes);
    });
    together(comm_, [&] { index.write_shared_part(path, total_nodes, first_node); });
    together(comm_, [&] {
      index.attach_shared(path, total_nodes, size);
      mine.seconds_index = seconds_since(start);
      budget_.set_frame_tets(MemoryBudget::frame_tets_for(header_memory(state_, options_)));
      if (options_.brick_labels) budget_.set_label_order_bytes(BrickReorder::job_bytes(index.view().count));
      plan = plan_triangulation(index, options_, budget_, threads_);
    });
  }

  const RunOptions& options_;
  Communicator& comm_;
  const std::string dir_;
  const io::OutputClaim* claim_;
  Checkpoint* checkpoint_;
  json& state_;  // the stages' records: saved in the checkpoint, or only held here
  const int threads_;
  MemoryBudget budget_;
  RunSummary summary_;
  StageClock::time_point start_ = StageClock::now();
};

}  // namespace

RunSummary run_job_distributed(const RunOptions& requested, Communicator& comm) {
  const bool root = comm.rank() == 0;
  RunOptions options;
  // The same checks on every rank (the same options): the same answer everywhere.
  together(comm, [&] {
    options = detail::capped_options(requested);
    if (io::is_std_stream(options.input) || io::is_std_stream(options.output))
      throw UsageError("under mpirun, the input and the output must be files (not - )");
  });

  // Rank 0: the user's files before anything else, as one process checks them
  // (pipeline/run.cpp), and the work directory every rank writes into: the job's
  // checkpoint (rank 0's state.json, rank R's rank-R.json and fragment beside it), or
  // a temporary directory.
  std::optional<io::OutputClaim> claim;
  std::optional<TempDir> tmp;
  std::optional<Checkpoint> checkpoint;
  detail::OpenedJob opened;
  std::string dir;
  together(comm, [&] {
    if (!root) return;
    io::refuse_input_as_output(options.input, options.output);
    for (const std::string& more : options.read.more_inputs) io::refuse_input_as_output(more, options.output);
    claim.emplace(options.output);
    if (options.checkpoint) {
      checkpoint.emplace(checkpoint_directory(options));
      opened = detail::open_checkpointed_job(options, *checkpoint, *claim, comm.size());
      dir = checkpoint->dir();
      // The split into ranks is part of the checkpoint (each rank's fragment holds its
      // labels' frames): a resume keeps it, checked before any rank writes.
      json& state = opened.state;
      if (!opened.finished) {
        const std::uint64_t recorded = state.value("ranks", std::uint64_t(comm.size()));
        if (recorded != std::uint64_t(comm.size())) {
          // The sort and rank 0's frames do not depend on the number of ranks; the
          // other ranks' records and fragments do (each held its rank's labels).
          spdlog::warn(
              "the job was started on {} ranks and goes on on {}: the sort and rank 0's frames are kept, "
              "the other ranks' labels are triangulated again",
              recorded, comm.size());
          remove_other_ranks_files(checkpoint->dir());
        }
        state["ranks"] = comm.size();
        checkpoint->save(state);
      }
    } else {
      detail::remove_stale_temporary_dirs(detail::work_parent(options));
      opened.disk = detail::plan_and_check_disk(options, detail::work_parent(options), false, comm.size());
      tmp.emplace(detail::work_parent(options), "tetstream-run");
      dir = tmp->dir();
    }
  });
  // The checkpointed job had finished (its checkpoint, every rank's files in it, is
  // gone): rank 0 reports it.
  if (comm.broadcast(opened.finished ? "finished" : "", 0) == "finished") return root ? *opened.finished : RunSummary{};
  dir = comm.broadcast(dir, 0);

  // Ranks 1 and up: their part of the checkpoint, beside rank 0's.
  std::optional<Checkpoint> member;
  json member_state = json::object();
  together(comm, [&] {
    if (root || !options.checkpoint) return;
    member.emplace(dir, rank_prefix(comm.rank()) + ".json");
    member->join();
    const json identity = detail::job_identity(options);
    if (member->exists()) {
      std::string difference;
      detail::trusting_checkpoint(*member, [&] {
        member_state = member->load();
        difference = detail::identity_difference(member_state.at("job"), identity);
        if (member_state.at("rank").get<int>() != comm.rank()) difference = "another rank's state";
      });
      if (!difference.empty())
        throw UsageError("cannot resume from " + member->path(rank_prefix(comm.rank()) + ".json") + ": " + difference +
                         "; " + detail::kHowToRestart);
    } else {
      member_state = {{"job", identity}, {"rank", comm.rank()}};
      member->save(member_state);
    }
  });

  RunSummary summary;
  std::exception_ptr failure;
  try {
    summary = RankJob(options, comm, dir, claim ? &*claim : nullptr,
                      root ? (checkpoint ? &*checkpoint : nullptr) : (member ? &*member : nullptr),
                      root ? opened.state : member_state)
                  .run();
  } catch (...) {
    failure = std::current_exception();
  }
  // Every rank's stages (and their files) are done with before rank 0 removes the
  // work directory or the checkpoint: every failure above was agreed on, so every
  // rank is here.
  comm.agree(0);
  if (failure) {
    if (!root) std::rethrow_exception(failure);
    if (checkpoint) {
      try {
        std::rethrow_exception(failure);
      } catch (...) {
        detail::rethrow_job_failure(*checkpoint, options);  // keeps it, or removes it with every rank's files
      }
    }
    // A job without a checkpoint leaves nothing behind (as in one process).
    if (claim && claim->created()) remove_file(options.output + ".partial");
    std::rethrow_exception(failure);
  }
  if (checkpoint) checkpoint->remove();  // rank 0's files and every rank's
  summary.disk_planned_bytes = opened.disk;
  return summary;
}

}  // namespace tetstream::pipeline
