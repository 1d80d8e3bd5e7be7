#include "pipeline/periodic/keep_stage.hpp"

#include "core/compiler.hpp"
#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_container.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/periodic/ball_grid.hpp"
#include "pipeline/periodic/keep_parts.hpp"
#include "pipeline/periodic/tet_records.hpp"
#include "pipeline/periodic/zone_keep.hpp"
#include "pipeline/run/stage_write.hpp"
#include "pipeline/write/async_tet_writer.hpp"

#include <fcntl.h>
#include <malloc.h>
#include <omp.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <deque>
#include <filesystem>
#include <limits>
#include <map>
#include <mutex>
#include <optional>

namespace tetstream::pipeline::periodic {

namespace {

using nlohmann::json;

// A bit a position, and how many are set before each: rank(i) in two reads.
class RankedBits {
 public:
  explicit RankedBits(std::uint64_t n = 0) : words_((n + 63) / 64, 0) {}
  void set(std::uint64_t i) { words_[i / 64] |= std::uint64_t(1) << (i % 64); }
  bool test(std::uint64_t i) const { return words_[i / 64] >> (i % 64) & 1; }
  void count() {
    before_.resize(words_.size() + 1);
    before_[0] = 0;
    for (std::size_t w = 0; w < words_.size(); ++w)
      before_[w + 1] = before_[w] + std::uint64_t(std::popcount(words_[w]));
  }
  // The bits set before position i (i up to n).
  std::uint64_t rank(std::uint64_t i) const {
    const std::uint64_t w = i / 64, b = i % 64;
    return before_[w] + (b ? std::uint64_t(std::popcount(words_[w] << (64 - b))) : 0);
  }
  std::uint64_t bytes() const { return 8 * (words_.size() + before_.size()); }

 private:
  std::vector<std::uint64_t> words_, before_;
};

// The padded labels' code words (keep_parts.hpp), from one pass over the sorted
// points: a padded label is a point of the box when its original index is below N,
// and its periodic label is then the number of the box's points before it (the
// periodic labels keep the padded job's lexicographic order); an image takes its
// point's. Held as a bit a padded label (a point of the box), the box's points
// counted before each word, and each image's word in padded order (found by the
// images before it: the label less the box's points before it). So a zone's code words cost reads of these tables
// alone, near one another for a window's labels, and no read of the sorted file.
class PeriodicLabels {
 public:
  PeriodicLabels(const SortedView& view, const KeepSetup& s, io::TetFileHeader& header, BallGrid& grid)
      : box_(view.count) {
    // Each point with images, by its rank among them: its periodic label, once met.
    RankedBits has_images(s.input_points);
    for (std::uint64_t code : s.images->code) has_images.set(code >> 3);
    has_images.count();
    std::vector<std::uint64_t> image_point_label(has_images.rank(s.input_points), 0);
    Bounds bounds;
    // (The images' slots grow a wave at a time: merged duplicates leave fewer labels
    // than points and images, so their count is known only as the waves go.)
    image_code_.reserve(view.count > s.input_points ? view.count - s.input_points : 0);
    // On every thread, a wave of blocks at a time (a block's bits are whole words, so
    // no two threads write one): the box's points of each block counted first, for
    // the labels and image slots each block starts at, then the block's words.
    const int threads = std::max(1, omp_get_max_threads());
    const std::uint64_t blocks = (view.count + kBlock - 1) / kBlock;
    const std::uint64_t wave = 4 * std::uint64_t(threads);
    std::vector<std::uint64_t> box_in(wave);  // a block's box points, then those before it
    view.points.visit([&](const auto* records) {
      // The padded job's sorted file is mapped read-only (as for the index's scans):
      // its pages are handed back behind the pass, which runs before the triangulation
      // sets the view's query tracker (a whole 10^6-point file mapped at once went 22%
      // past a 60M budget).
      ReleaseBehind behind(view.points, 0, true);
      const auto block_end = [&](std::uint64_t b) { return std::min(view.count, (b + 1) * kBlock); };
      for (std::uint64_t first = 0; first < blocks; first += wave) {
        const std::int64_t n = std::int64_t(std::min(wave, blocks - first));
#pragma omp parallel for schedule(static) num_threads(threads)
        for (std::int64_t i = 0; i < n; ++i) {
          const std::uint64_t b = first + std::uint64_t(i);
          std::uint64_t in = 0;
          for (std::uint64_t label = b * kBlock; label < block_end(b); ++label)
            in += records[label].original() < s.input_points;
          box_in[std::size_t(i)] = in;
        }
        for (std::int64_t i = 0; i < n; ++i) {  // each block's count becomes the box's points before it
          const std::uint64_t in = box_in[std::size_t(i)];
          box_in[std::size_t(i)] = points_;
          points_ += in;
        }
        image_code_.resize(block_end(first + std::uint64_t(n) - 1) - points_);
#pragma omp parallel num_threads(threads)
        {
          Bounds mine;
#pragma omp for schedule(static)
          for (std::int64_t i = 0; i < n; ++i) {
            const std::uint64_t b = first + std::uint64_t(i);
            std::uint64_t point = box_in[std::size_t(i)];
            std::uint64_t image = b * kBlock - point;  // the images before the block
            for (std::uint64_t label = b * kBlock; label < block_end(b); ++label) {
              const std::uint64_t original = records[label].original();
              double p[3];
              records[label].xyz(p);
              grid.mark(p);
              unsigned bits = 0;
              if (original < s.input_points) {
                box_.set(label);
                if (has_images.test(original)) image_point_label[has_images.rank(original)] = point;
                mine.add(p);
                ++point;
              } else {
                // Its point's periodic label may come later in the padded order (an
                // image below 0 comes before its point): its rank among the points
                // with images for now.
                const std::uint64_t c = s.images->code[original - s.input_points];
                bits = unsigned(c & 7);
                image_code_[image++] = has_images.rank(c >> 3) << 3 | bits;
              }
            }
          }
#pragma omp critical(periodic_labels_bounds)
          bounds.add(mine);
        }
        behind.reached(block_end(first + std::uint64_t(n) - 1) - 1);
      }
    });
    box_.count();
    const std::int64_t images = std::int64_t(image_code_.size());
#pragma omp parallel for schedule(static) num_threads(threads)
    for (std::int64_t i = 0; i < images; ++i) {
      std::uint64_t& c = image_code_[std::size_t(i)];
      c = image_point_label[c >> 3] << 4 | (c & 7);
    }
    for (int k = 0; k < 3; ++k) {
      header.bbox_min[k] = bounds.min[k];
      header.bbox_max[k] = bounds.max[k];
    }
  }

  std::uint64_t points() const { return points_; }
  // The box's points among the padded labels below `label`.
  std::uint64_t box_points_before(std::uint64_t label) const { return box_.rank(label); }

  std::uint64_t code(std::uint64_t label) const {
    const std::uint64_t before = box_.rank(label);
    const std::uint64_t word = box_.test(label) ? before << 4 : image_code_[label - before];
    return word;
  }

  std::uint64_t bytes() const { return box_.bytes() + 8 * image_code_.size(); }

 private:
  static constexpr std::uint64_t kBlock = std::uint64_t(1) << 16;  // labels a thread takes at once: whole words
  // The box's points' bounding box.
  struct Bounds {
    double min[3] = {kInf, kInf, kInf}, max[3] = {-kInf, -kInf, -kInf};
    static constexpr double kInf = std::numeric_limits<double>::infinity();
    void add(const double* p) {
      for (int k = 0; k < 3; ++k) min[k] = std::min(min[k], p[k]), max[k] = std::max(max[k], p[k]);
    }
    void add(const Bounds& o) {
      for (int k = 0; k < 3; ++k) min[k] = std::min(min[k], o.min[k]), max[k] = std::max(max[k], o.max[k]);
    }
  };
  RankedBits box_;
  std::vector<std::uint64_t> image_code_;
  std::uint64_t points_ = 0;
};

// A file the keep appends to, in the job's directory; a checkpoint records its length
// and CRC32C once synced, and a resumed job cuts it back there.
class AppendFile {
 public:
  AppendFile(std::string path, std::uint64_t keep_bytes) : path_(std::move(path)) {
    // A new job's file is made afresh; a resumed job's is the one its record names.
    fd_ = keep_bytes == 0 ? io::create_work_file(path_, O_RDWR) : io::open_work_file(path_);
    if (::ftruncate(fd_, off_t(keep_bytes)) != 0 || ::lseek(fd_, off_t(keep_bytes), SEEK_SET) < 0) {
      const std::string why = std::strerror(errno);
      ::close(fd_);
      throw IoError(path_ + ": cannot cut back: " + why);
    }
    bytes_ = keep_bytes;
  }
  ~AppendFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  AppendFile(const AppendFile&) = delete;
  AppendFile& operator=(const AppendFile&) = delete;

  void set_crc(std::uint32_t crc) { crc_ = crc; }
  void append(const void* data, std::size_t n) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    crc_ = io::crc32c(p, n, crc_);
    bytes_ += n;
    while (n > 0) {
      const ssize_t w = ::write(fd_, p, n);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) throw IoError(path_ + ": cannot write: " + std::strerror(errno));
      p += w;
      n -= std::size_t(w);
    }
  }
  void sync() {
    if (::fdatasync(fd_) != 0) throw IoError(path_ + ": cannot sync: " + std::strerror(errno));
  }
  // Bytes [from, from + n) into `out`.
  void read(std::uint64_t from, void* out, std::size_t n) const {
    auto* p = static_cast<std::uint8_t*>(out);
    while (n > 0) {
      const ssize_t r = ::pread(fd_, p, n, off_t(from));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) throw IoError(path_ + ": cannot read: " + std::strerror(errno));
      p += r;
      from += std::uint64_t(r);
      n -= std::size_t(r);
    }
  }
  std::uint64_t bytes() const { return bytes_; }
  std::uint32_t crc() const { return crc_; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t bytes_ = 0;
  std::uint32_t crc_ = 0;
};

constexpr const char* kDeferredFile = "periodic-deferred.tets";
constexpr const char* kOffsetsFile = "periodic-offsets.tets";
constexpr std::size_t kBlockTets = std::size_t(1) << 16;  // deferred tets read back at a time

class KeepStage final : public OutputStage {
 public:
  KeepStage(const StageContext& context, const SortedView& view, const TriangulateShares& shares,
            const KeepSetup& setup, KeepResult& result)
      : context_(context),
        view_(view),
        shares_(shares),
        s_(setup),
        result_(result),
        scratch_(std::size_t(std::max(context.options.threads, omp_get_max_threads()))) {}

  ~KeepStage() override {
    // The zones stop before this (the triangulation is destroyed first); the writer's
    // thread goes before the writer. A failed certificate empties the output: the
    // next margin's attempt starts it over under the same claim.
    async_.reset();
    if (abandoned_ && writer_) {
      try {
        writer_->discard();
      } catch (const std::exception& e) {
        spdlog::debug("periodic keep: discarding the output: {}", e.what());
      }
    }
  }

  void prepare() override;
  void run() override;
  void zone_done(std::size_t unit, ZoneTets& tets) override;
  void add_segment(const std::vector<ZoneTets>& parts, const SegmentStats& work, std::uint64_t points,
                   std::uint64_t next_label) override;
  void commit(std::uint64_t end_label) override;
  void finish() override;
  std::uint64_t end_sort_bytes() const;

  double busy_seconds() const override { return async_ ? async_->busy_seconds() : 0; }
  double producer_wait_seconds() const override { return async_ ? async_->producer_wait_seconds() : 0; }
  std::uint64_t bytes_written() const override { return writer_ ? writer_->bytes_written() : output_bytes_; }
  std::uint64_t tet_bytes() const override { return writer_ ? writer_->tet_bytes() : 0; }

 private:
  std::uint64_t frontier(std::uint64_t padded_label) const;
  void emit_frame(std::vector<std::uint64_t>& labels, std::vector<std::uint16_t>& codes);
  void save_offsets();
  void write(const KeptTet& t);
  void defer(std::span<const KeptTet> tets) { deferred_->append(tets.data(), tets.size_bytes()); }
  void record(std::uint64_t next_label, bool finishing);
  void restore(const json& rec);
  void merge_deferred();

  StageContext context_;
  const SortedView& view_;
  const TriangulateShares shares_;
  const KeepSetup& s_;
  KeepResult& result_;
  CentreBox box_;  // C, where the kept tets' circumcentres lie, and the padded box
  io::TetFileHeader header_;
  std::optional<BallGrid> grid_;
  std::optional<PeriodicLabels> labels_;
  std::unique_ptr<io::TetWriter> writer_;
  std::optional<AsyncTetWriter> async_;
  std::optional<AppendFile> deferred_, offsets_file_;
  io::PeriodicOffsetsWriter offsets_;  // POFS, filled on the segments' thread in frame order
  // Frames' compressed offsets not yet in offsets_file_ (a checkpointed job's): the
  // writer's thread appends those of the frames written before each record.
  std::mutex unsaved_mutex_;
  std::deque<std::vector<std::uint8_t>> unsaved_offsets_;
  std::uint64_t offsets_in_file_ = 0;  // frames (the writer's thread's)
  std::optional<FrameFeeder> feeder_;
  std::uint64_t deferred_from_ = 0;  // tets of m from here on are written last (deferred)
  // The kept tets at or past the frontier, sorted, waiting for the next segments; past
  // waiting_cap_ of them everything goes through the deferred file (spilling_).
  std::vector<KeptTet> waiting_, still_waiting_;
  std::size_t waiting_cap_ = 1, peak_waiting_ = 0;
  bool spilling_ = false;
  std::uint64_t last_ = 0;  // the last m written (a wrong frontier is refused, never written)
  // Each zone thread's buffers (by omp_get_thread_num()), kept from zone to zone:
  // fresh pages for each zone would cost their zeroing.
  struct Scratch {
    std::vector<ZoneVertex> vx;
    std::vector<std::pair<KeptTet, std::array<std::uint32_t, 4>>> apart;
    std::vector<std::uint32_t> deferred;
  };
  std::vector<Scratch> scratch_;
  std::mutex zones_mutex_;
  std::map<std::size_t, ZoneKept> zones_;  // by unit, until its segment is added
  std::vector<std::vector<std::uint64_t>> spare_codes_;
  std::size_t next_unit_ = 0;  // the unit of the next segment's first zone
  std::uint64_t long_edges_ = 0;
  bool safe_edges_ = false;
  std::uint64_t certified_ = 0, balls_ = 0;  // this process's: tets that may meet C, circumspheres computed
  int label_bits_ = 1;
  bool resumed_ = false, finishing_ = false, done_ = false;
  std::atomic<bool> abandoned_{false};  // set by a zone's thread
  std::uint64_t output_bytes_ = 0;
  std::atomic<double> zone_seconds_{0};
};

void KeepStage::prepare() {
  const auto t0 = StageClock::now();
  box_ = centre_box(s_.period, s_.margin);
  header_.coord_type = io::CoordType::kFloat64;
  header_.tool = "tetstream 0.1.0";
  header_.options = s_.options_json;
  header_.input_count = s_.input_points;
  // Cells of about 16 points of uniform data (2.52 mean spacings): the sphere is skipped
  // for the tets of the roomy points, (1 + sqrt(2)) sqrt(3) c (~10.5 spacings) inside the
  // padded box, and a uniform set leaves a cell empty about once in 10^7 points.
  const double spacing =
      std::cbrt(s_.period[0] * s_.period[1] * s_.period[2] / double(std::max<std::uint64_t>(s_.input_points, 1)));
  grid_.emplace(box_.lower, s_.period, 2.52 * spacing);
  labels_.emplace(view_, s_, header_, *grid_);
  const double labelled = seconds_since(t0);
  grid_->finish();
  spdlog::debug("periodic keep: code tables in {:.3f}s, ball grid in {:.3f}s", labelled, seconds_since(t0) - labelled);
  // Safe tets are far below CGAL's edge limit once the box is some 25 spacings wide.
  const double l = std::min({s_.period[0], s_.period[1], s_.period[2]});
  safe_edges_ = grid_->diameter_bound() < std::sqrt(0.166) * l * (1 - 0x1p-20);
  header_.point_count = labels_->points();
  // A zone's vertex keeps its place beside its code word (zone_keep.hpp, ZoneVertex).
  if (labels_->points() >> (ZoneVertex::kPlaceShift - 4) != 0)
    throw InputError(s_.input + ": more than 2^48 points in one periodic box");
  label_bits_ = std::max(1, int(std::bit_width(labels_->points())));

  io::TetWriterOptions wo;
  wo.claim = s_.claim;
  wo.threads = shares_.encoders;
  wo.buffer_bytes = shares_.file_buffer_bytes;
  wo.keep_partial = context_.checkpoint != nullptr;
  const json& state = context_.state;
  resumed_ = state.contains("keep");
  if (!resumed_) {
    writer_ = std::make_unique<io::TetWriter>(s_.output, header_, wo);
  } else {
    const json& rec = state["keep"];
    const std::uint64_t committed = rec.at("committed").get<std::uint64_t>();
    finishing_ = rec.value("finishing", false);
    std::error_code ec;
    // The job's claim made the partial file afresh (it was not there): the output
    // had been renamed into place.
    if (finishing_ && s_.claim->created() && std::filesystem::exists(s_.output, ec)) {
      // Renamed into place: only the checkpoint's removal was cut short.
      const io::TetReader finished(s_.output, io::TetReader::Periodic::kAccept);  // throws unless complete
      done_ = true;
      output_bytes_ = finished.file_bytes();
      first_label_ = view_.count;
      result_.points = finished.point_count();
      result_.tets = finished.tet_count();
    } else {
      try {
        writer_ = io::TetWriter::resume(s_.output, header_, committed, wo);
      } catch (const InputError& e) {
        throw DamagedCheckpoint(std::string(e.what()) + " (damaged checkpoint)");
      }
    }
    work_ = counters_from(rec.at("counters"));
    segments_resumed_ = segments_done_ = rec.at("segments").get<std::uint64_t>();
    if (!done_) first_label_ = rec.at("next_label").get<std::uint64_t>();
  }
  if (!done_) {
    const std::uint64_t keep_deferred = resumed_ ? state["keep"].at("deferred_bytes").get<std::uint64_t>() : 0;
    const std::uint64_t keep_offsets = resumed_ ? state["keep"].at("offsets_bytes").get<std::uint64_t>() : 0;
    deferred_.emplace(context_.dir + "/" + kDeferredFile, keep_deferred);
    offsets_file_.emplace(context_.dir + "/" + kOffsetsFile, keep_offsets);
    feeder_.emplace([this](std::vector<std::uint64_t>& l, std::vector<std::uint16_t>& c) { emit_frame(l, c); },
                    s_.frame_tets);
    const int axis = view_.axis;
    // A kept tet whose m lies at its image across the sort axis' lower face has m's
    // point within the margin of the upper face (the points with such images): those
    // tets, which come first in the padded order, are written last.
    deferred_from_ =
        labels_->box_points_before(view_.lower_bound(s_.period[std::size_t(axis)] - s_.margin[std::size_t(axis)]));
    waiting_cap_ = std::max<std::size_t>(1, std::size_t(s_.waiting_bytes / sizeof(KeptTet)));
    if (resumed_) restore(state["keep"]);
  }
  if (resumed_)
    spdlog::info("periodic keep: resuming after {} segments of the padded job, labels from {} of {}", segments_resumed_,
                 first_label_, view_.count);
  seconds_ += seconds_since(t0);
}

// The record's files back: each checked against the CRC the record gives it.
void KeepStage::restore(const json& rec) {
  const auto read_tets = [this](const json& file) {
    std::vector<KeptTet> tets(file.at("tets").get<std::size_t>());
    if (!tets.empty())
      read_file_exactly(context_.checkpoint->path(file.at("name").get<std::string>()), tets.data(),
                        tets.size() * sizeof(KeptTet), file.at("crc32c").get<std::uint32_t>());
    return tets;
  };
  const auto check = [](const AppendFile& f, const json& crc) {
    if (!region_matches(f.path(), 0, f.bytes(), crc.get<std::uint32_t>()))
      throw DamagedCheckpoint(f.path() + ": damaged checkpoint (checksum mismatch)");
  };
  check(*deferred_, rec.at("deferred_crc32c"));
  deferred_->set_crc(rec.at("deferred_crc32c").get<std::uint32_t>());
  check(*offsets_file_, rec.at("offsets_crc32c"));
  offsets_file_->set_crc(rec.at("offsets_crc32c").get<std::uint32_t>());
  // Each frame's compressed offsets: its tet count and byte count, then the bytes.
  std::vector<std::uint8_t> block;
  std::uint64_t frames = 0;
  for (std::uint64_t at = 0; at < offsets_file_->bytes(); ++frames) {
    std::uint32_t sizes[2];
    offsets_file_->read(at, sizes, sizeof sizes);
    block.resize(sizes[1]);
    offsets_file_->read(at + sizeof sizes, block.data(), block.size());
    offsets_.add_compressed(block, sizes[0]);
    at += sizeof sizes + block.size();
  }
  if (frames != writer_->frames_written())
    throw DamagedCheckpoint(offsets_file_->path() + ": damaged checkpoint (" + std::to_string(frames) +
                            " frames of offsets, " + std::to_string(writer_->frames_written()) + " frames)");
  offsets_in_file_ = frames;
  feeder_->restore(read_tets(rec.at("pending")), rec.at("kept").get<std::uint64_t>());
  waiting_ = read_tets(rec.at("waiting"));
  last_ = rec.at("last").get<std::uint64_t>();
  spilling_ = rec.at("spilling").get<bool>();
  long_edges_ = rec.at("long_edges").get<std::uint64_t>();
}

void KeepStage::run() {
  if (done_) return;
  const std::size_t encoders = std::size_t(std::max(1, shares_.encoders));
  async_.emplace(*writer_, encoders, encoders);
  if (resumed_) return;
  // The box's points in label order (their periodic labels), then PBOX, on the
  // writer's thread while the first zones are triangulated.
  async_->add_task([this](io::TetWriter& w) {
    constexpr std::size_t kPoints = std::size_t(1) << 16;
    std::vector<double> xyz;
    std::vector<std::uint64_t> ids;
    view_.points.visit([&](const auto* records) {
      ReleaseBehind behind(view_.points, 0, true);  // the mapped sorted file (PeriodicLabels)
      for (std::uint64_t first = 0; first < view_.count; first += kPoints) {
        const std::uint64_t end = std::min<std::uint64_t>(view_.count, first + kPoints);
        xyz.clear();
        ids.clear();
        for (std::uint64_t label = first; label < end; ++label) {
          const std::uint64_t original = records[label].original();
          if (original >= s_.input_points) continue;
          double p[3];
          records[label].xyz(p);
          xyz.insert(xyz.end(), p, p + 3);
          ids.push_back(original);
        }
        w.add_points(xyz.data(), ids.data(), ids.size());
        behind.reached(end - 1);
      }
    });
    w.add_section(io::kTagPeriodicBox, io::serialize_periodic_box(io::PeriodicBox{s_.period, view_.axis}));
  });
  record(0, false);
}

// On the zone's thread: its window's code words, and its tets certified and kept in
// place, in the stored order (zone_keep.hpp).
void KeepStage::zone_done(std::size_t unit, ZoneTets& z) {
  const auto t0 = StageClock::now();
  Scratch& scratch = scratch_.at(std::size_t(omp_get_thread_num()));
  std::vector<ZoneVertex>& vx = scratch.vx;
  ZoneKept kept;
  {
    const std::lock_guard lock(zones_mutex_);
    if (!spare_codes_.empty()) {
      kept.code = std::move(spare_codes_.back());
      spare_codes_.pop_back();
    }
  }
  const std::size_t n = z.labels.size();
  kept.code.resize(n);
  vx.resize(n);
  // The window's coordinates are the zone worker's (ZoneTets::xyz), read in order.
  if (z.xyz.size() < 3 * n) throw std::logic_error("periodic keep: a zone came without its coordinates");
  const double* xyz = z.xyz.data();
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint64_t code = kept.code[i] = labels_->code(z.labels[i]);
    const std::uint64_t place = vertex_place(xyz + 3 * i, grid_->safe(xyz + 3 * i), grid_->radius_bound(), box_);
    vx[i].word = code | place << ZoneVertex::kPlaceShift;
    vx[i].axis = xyz[3 * i + std::size_t(view_.axis)];
  }
  if (!keep_zone(z, kept, vx, xyz, box_, deferred_from_, safe_edges_, scratch.apart, scratch.deferred)) {
    abandoned_ = true;
    throw BallsLeaveBox(s_.input + ": a Delaunay ball near the box of circumcentres leaves the padded box");
  }
  {
    const std::lock_guard lock(zones_mutex_);
    zones_[unit] = std::move(kept);
  }
  double s = zone_seconds_.load();
  while (!zone_seconds_.compare_exchange_weak(s, s + seconds_since(t0))) {
  }
}

// The smallest periodic label a kept tet can have when every tet still to come has its
// padded labels at `padded_label` or past (docs/periodic.md, "Why the padded order
// almost is the periodic one"): the box's points before that label's coordinate.
std::uint64_t KeepStage::frontier(std::uint64_t padded_label) const {
  if (padded_label >= view_.count) return labels_->points();
  return labels_->box_points_before(view_.lower_bound(view_.read_key(padded_label)));
}

// The segment's zones' kept tets (each zone: a run in order and one sorted apart) and
// the tets still waiting, merged in the stored order: those below the frontier to the
// output, the others waiting for the next segments; the deferred ones to their file.
void KeepStage::add_segment(const std::vector<ZoneTets>& parts, const SegmentStats& work, std::uint64_t points,
                            std::uint64_t next_label) {
  const auto t0 = StageClock::now();
  std::vector<ZoneKept> kept(parts.size());
  {
    const std::lock_guard lock(zones_mutex_);
    for (std::size_t p = 0; p < parts.size(); ++p) {
      auto it = zones_.find(next_unit_ + p);
      if (it == zones_.end()) throw std::logic_error("periodic keep: a zone's tets were not kept");
      kept[p] = std::move(it->second);
      zones_.erase(it);
    }
  }
  next_unit_ += parts.size();
  // The runs to merge: [begin, end) of a zone's tets, and the waiting tets (part
  // null: waiting_ from `at`), each with its head, the next tet it gives.
  struct Run {
    const ZoneTets* part;
    const ZoneKept* kept;
    std::size_t at, end;
    KeptTet head;
  };
  std::vector<Run> runs;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    const std::size_t bounds[3] = {0, kept[p].in_order_end, kept[p].sorted_end};
    for (int r = 0; r < 2; ++r)
      if (bounds[r] < bounds[r + 1]) runs.push_back({&parts[p], &kept[p], bounds[r], bounds[r + 1], {}});
  }
  for (Run& r : runs) r.head = kept_tet(&r.part->tets[4 * r.at], r.kept->code);
  if (!waiting_.empty()) runs.push_back({nullptr, nullptr, 0, waiting_.size(), waiting_[0]});
  const std::uint64_t f = frontier(next_label);
  const KeptTetLess less;
  still_waiting_.clear();
  const std::size_t spill_batch = std::min(waiting_cap_, kBlockTets);
  // The run with the smallest head gives its tets while they stay below every other
  // run's head (the zones' runs are long stretches of labels): one comparison a tet,
  // and a search of the heads only where the run changes.
  for (;;) {
    Run* best = nullptr;
    const KeptTet* bound = nullptr;  // the smallest head of the others
    for (Run& r : runs) {
      if (r.at >= r.end) continue;
      if (!best || less(r.head, best->head)) {
        if (best) bound = &best->head;
        best = &r;
      } else if (!bound || less(r.head, *bound)) {
        bound = &r.head;
      }
    }
    if (!best) break;
    do {
      const KeptTet& t = best->head;
      if (!spilling_ && t.v[0] < f) {
        write(t);
      } else {
        still_waiting_.push_back(t);
        if (still_waiting_.size() >= (spilling_ ? spill_batch : waiting_cap_)) {
          // Past the share (or a spill's batch): to the deferred file, which the external
          // sort orders at the end, and the rest of the job after it (the tets written
          // so far precede every one of these: they were below the frontier).
          if (!spilling_) spdlog::debug("periodic keep: tets far out of order, the rest through the external sort");
          spilling_ = true;
          defer(still_waiting_);
          still_waiting_.clear();
        }
      }
      if (++best->at >= best->end) break;
      if (!best->part) {
        best->head = waiting_[best->at];
        continue;
      }
      const std::uint32_t* q = &best->part->tets[4 * best->at];
      if (best->at + 8 < best->end)
        for (int j = 0; j < 4; ++j) TS_PREFETCH(&best->kept->code[q[32 + j]]);
      best->head = kept_tet(q, best->kept->code);
    } while (!bound || less(best->head, *bound));
  }
  if (spilling_) {
    // Tets far out of order (a shape this frontier does not suit): they and all the
    // rest go through the external sort, which then writes them in order; the lists
    // hold at most a batch.
    defer(still_waiting_);
    still_waiting_ = {};
    waiting_ = {};
  } else {
    waiting_.swap(still_waiting_);
    peak_waiting_ = std::max(peak_waiting_, waiting_.size());
  }
  // The deferred tets, in any order: the external sort orders them at the end.
  std::vector<KeptTet> tail;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    tail.clear();
    for (std::size_t i = kept[p].sorted_end; i < parts[p].size(); ++i)
      tail.push_back(kept_tet(&parts[p].tets[4 * i], kept[p].code));
    defer(tail);
    long_edges_ += kept[p].long_edges;
    certified_ += kept[p].certified;
    balls_ += kept[p].balls;
  }
  {
    // The code tables back to the zones to come: their pages are already there.
    const std::lock_guard lock(zones_mutex_);
    for (ZoneKept& k : kept) spare_codes_.push_back(std::move(k.code));
    while (spare_codes_.size() > parts.size() + 2) spare_codes_.pop_back();
  }
  work_.stats += work;
  work_.segment_labels += points;
  ++segments_done_;
  record(next_label, false);
  seconds_ += seconds_since(t0);
}

// One kept tet to the output, in the stored order; a tet before the last one written
// would mean a wrong frontier: refused, never written.
void KeepStage::write(const KeptTet& t) {
  if (t.v[0] < last_)
    throw std::logic_error("periodic keep: a tet of label " + std::to_string(t.v[0]) +
                           " came after the frontier passed it");
  last_ = t.v[0];
  feeder_->add_one(t);
}

// A frame to the writer's thread; with several encoders its offsets compressed here (a
// few microseconds a frame), so that nothing but frames goes between the frames in the writer's queue: it
// takes the frames queued together and encodes them on its threads, as the plain write
// stage's (a task after each frame had it encode one frame at a time, on one thread).
void KeepStage::emit_frame(std::vector<std::uint64_t>& labels, std::vector<std::uint16_t>& codes) {
  const auto compress = [this](std::span<const std::uint16_t> frame) {
    const std::span<const std::uint8_t> z = offsets_.add_frame(frame);
    if (!context_.checkpoint) return;
    // For the checkpoint's file: its tet count and byte count, then the bytes.
    const std::uint32_t sizes[2] = {std::uint32_t(frame.size()), std::uint32_t(z.size())};
    std::vector<std::uint8_t> block(sizeof sizes + z.size());
    std::memcpy(block.data(), sizes, sizeof sizes);
    std::copy(z.begin(), z.end(), block.begin() + sizeof sizes);
    const std::lock_guard lock(unsaved_mutex_);
    unsaved_offsets_.push_back(std::move(block));
  };
  // With one encoder (a small budget) nothing is gathered: the writer's thread
  // compresses the offsets too, as a task behind the frame.
  const bool here = shares_.encoders > 1;
  if (here) compress(codes);
  // Queued before the next buffer is taken, as the plain write stage's FrameCutter:
  // while the queue is full, 2 x encoders + 1 frames are alive, what the writer's
  // share holds (taken first, the next was one more: 2 MiB over --memory 68M).
  async_->add_tets(std::move(labels));
  labels = async_->take_buffer();
  labels.reserve(4 * s_.frame_tets + 4096);  // a frame and a group's overrun
  if (!here)
    async_->add_task([compress, frame = std::vector<std::uint16_t>(codes)](io::TetWriter&) { compress(frame); });
}

// On the writer's thread (or after a drain): the offsets of the frames written so far
// into the checkpoint's file, which then holds exactly those of the committed frames.
void KeepStage::save_offsets() {
  const std::uint64_t frames = writer_->frames_written();
  const std::lock_guard lock(unsaved_mutex_);
  for (; offsets_in_file_ < frames; ++offsets_in_file_) {
    if (unsaved_offsets_.empty()) throw std::logic_error("periodic keep: a frame written without its offsets");
    offsets_file_->append(unsaved_offsets_.front().data(), unsaved_offsets_.front().size());
    unsaved_offsets_.pop_front();
  }
  offsets_file_->sync();
}

// Records that the output holds every kept tet of the padded labels below
// `next_label` but those the record keeps beside it (the frame being filled, the tets
// waiting for the frontier, the deferred ones): saved by the writer's thread once the
// frames before it are on disk (`finishing`: at once, after a drain), so the segments
// never wait for the writer. The files of the previous record go after the new one is saved.
void KeepStage::record(std::uint64_t next_label, bool finishing) {
  Checkpoint* checkpoint = context_.checkpoint;
  if (!checkpoint) return;
  deferred_->sync();
  json& state = context_.state;
  const auto save_tets = [&](const char* kind, const std::vector<KeptTet>& tets) {
    const std::string name = std::string("periodic-") + kind + "-" + std::to_string(segments_done_) + ".tets";
    if (!tets.empty()) write_file_atomically(context_.dir, name, tets.data(), tets.size() * sizeof(KeptTet));
    return json{
        {"name", name}, {"tets", tets.size()}, {"crc32c", io::crc32c(tets.data(), tets.size() * sizeof(KeptTet))}};
  };
  std::vector<std::string> old;
  if (state.contains("keep")) {
    for (const char* kind : {"pending", "waiting"}) {
      const std::string name = state["keep"][kind].value("name", "");
      if (!name.empty() && state["keep"][kind].value("tets", 0) > 0) old.push_back(checkpoint->path(name));
    }
  }
  state["keep"] = {{"committed", 0},
                   {"next_label", next_label},
                   {"segments", segments_done_},
                   {"counters", counters_json(work_)},
                   {"pending", save_tets("pending", feeder_->pending())},
                   {"waiting", save_tets("waiting", waiting_)},
                   {"kept", feeder_->count()},
                   {"last", last_},
                   {"spilling", spilling_},
                   {"long_edges", long_edges_},
                   {"deferred_bytes", deferred_->bytes()},
                   {"deferred_crc32c", deferred_->crc()},
                   {"offsets_bytes", 0},
                   {"offsets_crc32c", 0},
                   {"finishing", finishing}};
  // A file of the new record with the name of an old one is the new one's (same segment count).
  const json& rec = state["keep"];
  std::erase_if(old, [&](const std::string& path) {
    return path == checkpoint->path(rec["pending"]["name"]) || path == checkpoint->path(rec["waiting"]["name"]);
  });
  // On the writer's thread (or after a drain): the frames' offsets written so far are
  // those of the frames committed.
  auto persist = [this, checkpoint, old, disk = context_.disk, offsets = &*offsets_file_](json saved,
                                                                                          std::uint64_t committed) {
    save_offsets();
    saved["keep"]["committed"] = committed;
    saved["keep"]["offsets_bytes"] = offsets->bytes();
    saved["keep"]["offsets_crc32c"] = offsets->crc();
    checkpoint->save(std::move(saved));
    for (const std::string& path : old) remove_file(path);
    if (disk) disk->sample();
  };
  if (finishing) {
    const std::uint64_t committed = async_->checkpoint();  // drains first
    persist(state, committed);
    state["keep"]["committed"] = committed;
    state["keep"]["offsets_bytes"] = offsets_file_->bytes();
    state["keep"]["offsets_crc32c"] = offsets_file_->crc();
  } else {
    async_->add_checkpoint([persist, saved = state](std::uint64_t committed) { persist(saved, committed); });
  }
}

// The deferred tets (kept at an image below 0 on the sort axis, and all after a
// spill), sorted by the external sort from their file, to the output after the rest.
// The tets kept at images below 0 on the sort axis, sorted and written last. After the
// triangulation: in what its windows, query pages and shared rim gave back (at a small
// budget those are less than the setup's share), and never less than the sorter's 4 MiB.
std::uint64_t KeepStage::end_sort_bytes() const {
  const std::uint64_t freed = std::uint64_t(shares_.window_bytes) + shares_.query_page_bytes + shares_.shared_rim_bytes;
  return std::max<std::uint64_t>(std::min(s_.sort_bytes, freed), 4 << 20);
}

void KeepStage::merge_deferred() {
  // The block the file is read back through is inside the share (an eighth of it, at
  // most kBlockTets), and gone before the merge, whose windows and output take the
  // sorter's whole budget: beside it, the block was 2.6 MB over --memory at 66M.
  const std::size_t bytes = std::size_t(end_sort_bytes());
  const std::size_t block_tets = std::clamp<std::size_t>(bytes / 8 / sizeof(KeptTet), 1024, kBlockTets);
  ExternalSorter<KeptTet, KeptTetLess> sorter(
      sort_options(bytes - block_tets * sizeof(KeptTet), context_.dir, "periodic-tets"));
  const int bits = label_bits_;
  sorter.set_run_sort([bits](KeptTet* d, std::size_t n) { radix_sort_kept(d, n, bits); }, sizeof(KeptTet));
  {
    std::vector<KeptTet> block(block_tets);
    const std::uint64_t count = deferred_->bytes() / sizeof(KeptTet);
    for (std::uint64_t first = 0; first < count; first += block.size()) {
      const std::size_t k = std::size_t(std::min<std::uint64_t>(block.size(), count - first));
      deferred_->read(first * sizeof(KeptTet), block.data(), k * sizeof(KeptTet));
      sorter.push(std::span<const KeptTet>(block.data(), k));
    }
  }
  sorter.merge([this](std::span<const KeptTet> batch) {
    for (const KeptTet& t : batch) write(t);
  });
}

void KeepStage::commit(std::uint64_t /*end_label*/) {
  const auto t0 = StageClock::now();
  if (done_ || finishing_) return;
  if (long_edges_ != 0) throw long_edges_error(s_.input, long_edges_);
  // The zones are over: their tables go before the last sort takes its share.
  spare_codes_ = {};
  for (Scratch& scratch : scratch_) scratch = Scratch{};
  malloc_trim(0);
  for (const KeptTet& t : waiting_) write(t);
  waiting_.clear();
  merge_deferred();
  feeder_->flush();
  if (context_.checkpoint) {
    record(view_.count, true);
  } else {
    async_->drain();
  }
  seconds_ += seconds_since(t0);
}

void KeepStage::finish() {
  const auto t0 = StageClock::now();
  if (!done_) {
    async_->add_task([this](io::TetWriter& w) { w.add_section(io::kTagPeriodicOffsets, offsets_.payload()); });
    async_->finish();
    output_bytes_ = writer_->bytes_written();
    result_.points = labels_->points();
    result_.tets = writer_->tets_written();
  }
  result_.output_bytes = output_bytes_;
  result_.memory_shares = {{"keep", "sort", end_sort_bytes()}};
  result_.complete = true;
  seconds_ += seconds_since(t0);
  spdlog::debug(
      "periodic keep: {:.2f}s in the zones (summed over threads), {:.2f}s in the segments and the end; {} tets "
      "that may meet the box of centres covered, {} circumspheres computed (the other tets by the ball grid); at "
      "most {} tets waited for the frontier (room for {})",
      zone_seconds_.load(), seconds_, certified_, balls_, peak_waiting_, waiting_cap_);
}

}  // namespace

std::unique_ptr<OutputStage> make_keep_stage(const StageContext& context, const SortedView& view,
                                             const TriangulateShares& shares, const KeepSetup& setup,
                                             KeepResult& result) {
  return std::make_unique<KeepStage>(context, view, shares, setup, result);
}

std::uint64_t keep_stage_bytes(std::uint64_t padded_points, std::uint64_t input_points, std::uint64_t images,
                               std::uint64_t waiting_bytes, int threads) {
  // The rank tables (a bit and a count a word of 64: 1/4 byte a position), the images'
  // code words and, while they are made, the labels of the points with images (8 bytes an image each), the waiting
  // tets (twice: the merge makes the next list beside the last), the offsets
  // (compressed: a tenth of a byte a tet, 7 tets a point), the ball grid (two bytes a
  // cell of about 16 points), the zones' code tables held for their segment (8 bytes a
  // window point: about a byte a padded point), and each zone thread's buffers (16
  // bytes a window point, a window taken as a 32nd of the points: its code word with its
  // place and its sort axis coordinate, zone_keep.hpp).
  return padded_points / 4 + input_points / 4 + 16 * images + 2 * waiting_bytes + padded_points / 2 +
         padded_points / 8 + padded_points + std::uint64_t(std::max(threads, 1)) * 16 * padded_points / 32 + (1 << 20);
}

}  // namespace tetstream::pipeline::periodic
