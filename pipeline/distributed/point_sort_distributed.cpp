#include "pipeline/distributed/point_sort_distributed.hpp"

#include "pipeline/util/fault.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/sort/point_sort_detail.hpp"
#include "pipeline/sort/points_in_output.hpp"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>
#include <unordered_set>

namespace tetstream::pipeline {

namespace {

using namespace sort_detail;  // the pieces both sorts share

// The keys a rank samples: ~1024 a rank, so rank 0 sorts ~1024 K of them (24 KB a
// rank) and each range holds N/K points within a few per cent on smooth inputs.
constexpr std::size_t kSamplesPerRank = 1024;

// A point's coordinates in the sort's order (the axis first). Splitters are keys: the
// ranges they cut hold every point of equal coordinates on one side.
struct Key {
  double c[3];
};
Key key_of(const double* xyz, int axis) { return Key{{xyz[axis], xyz[(axis + 1) % 3], xyz[(axis + 2) % 3]}}; }
bool key_less(const Key& a, const Key& b) {
  for (int k = 0; k < 3; ++k)
    if (a.c[k] != b.c[k]) return a.c[k] < b.c[k];
  return false;
}
// The rank whose range holds `k`: how many splitters are at or before it. Monotone in
// the sort order, so the ranks' ranges follow each other in label order.
std::size_t rank_of(const std::vector<Key>& splitters, const Key& k) {
  return std::size_t(std::upper_bound(splitters.begin(), splitters.end(), k, key_less) - splitters.begin());
}

template <class T>
std::string to_bytes(const std::vector<T>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}
template <class T>
std::vector<T> from_bytes(const std::string& s) {
  std::vector<T> v(s.size() / sizeof(T));
  std::memcpy(v.data(), s.data(), v.size() * sizeof(T));
  return v;
}

// This rank's part of the points section, written at its place, its checksum kept
// for rank 0 to combine.
class PartSink final : public SortedSink {
 public:
  PartSink(io::OutputPart& out, std::uint64_t offset) : out_(out), payload_(out.fd(), out.path(), offset) {}
  void write(const void* data, std::size_t bytes) override { payload_.write(data, bytes); }
  void finish(SortedPoints& result, bool sync) override {
    payload_.flush();
    if (sync) out_.sync();
    result.crc32c = payload_.crc();
  }

 private:
  io::OutputPart& out_;
  PayloadWriter payload_;
};

// This rank's range of the input: records [first, end) of `count`.
struct InputRange {
  std::uint64_t count = 0, first = 0, end = 0;
};

// Moves a fresh reader to point `first` (this rank's range).
void skip_to(io::PointReader& reader, std::uint64_t first) {
  if (reader.skip(first) != first)
    throw InputError(reader.source_name() + ": changed while being read (ended before point " + std::to_string(first) +
                     ")");
}

// Reads exactly n points (the input's count said they are there).
void read_exactly(io::PointReader& reader, double* xyz, std::size_t n) {
  for (std::size_t got = 0; got < n;) {
    const std::size_t k = reader.read(xyz + 3 * got, std::min(n - got, kReadChunk));
    if (k == 0) throw InputError(reader.source_name() + ": changed while being read (ended early)");
    got += k;
  }
}

// The exchange and the merge, in records R. Fills `result`'s count, duplicates, runs,
// hull labels (this rank's, from 0) and crc32c (of this rank's part); returns the
// offset where its part was written.
template <class R>
std::uint64_t exchange_and_merge(Communicator& comm, const std::string& input, const io::PointReadOptions& read_options,
                                 const PointSortOptions& options, const std::string& dir, const std::string& runs_name,
                                 const InputRange& range, const std::vector<Key>& splitters, io::OutputPart& out,
                                 const DistributedSortTarget& target, SortedPoints& result) {
  const std::size_t ranks = std::size_t(comm.size());
  const bool root = comm.rank() == 0;
  const int axis = result.axis;
  std::optional<MemoryBudget> own_budget;
  const SortShares shares = sort_shares(options, result.input_count, own_budget);
  const std::size_t run_points = options.run_points ? options.run_points : shares.run_points;
  // A round: each rank reads `chunk` records and sends them on; a rank receives at
  // most `ranks` chunks. The send buffer and the read chunk come out of the run
  // buffer, which keeps room for one round's receipts (MPI's counts stay below 2^31).
  const std::size_t chunk =
      std::max<std::size_t>(1, std::min(run_points / (4 * ranks), (std::size_t(1) << 30) / ranks));
  const std::size_t capacity = std::max(run_points > 2 * chunk ? run_points - 2 * chunk : 0, ranks * chunk);

  ExternalSortOptions sorter_options;
  sorter_options.memory_bytes = shares.merge_bytes;
  sorter_options.dir = dir;
  sorter_options.name = runs_name;
  typename RecordSort<R>::Sorter sorter(sorter_options, typename RecordSort<R>::Less{axis});
  std::unordered_set<std::uint64_t> hull_originals;  // original indices of candidates
  // The exchange carries the container's records (R: 16 bytes for float32 input of at
  // most 2^32 points, 28 for float64; 32 only past 2^32), not the 32-byte SortedPoint.
  std::vector<SortedPoint> run;
  std::vector<R> send(chunk);
  run.reserve(capacity);
  std::vector<double> xyz(3 * chunk), run_xyz;
  std::vector<std::uint64_t> run_hull;
  auto flush = [&] {
    if (run.empty()) return;
    sort_detail::sort_and_push_run<R>(sorter, run, axis, shares, run_xyz, run_hull, hull_originals, result.runs);
    run.clear();
  };

  std::unique_ptr<io::PointReader> reader;
  together(comm, [&] {
    reader = io::open_points(input, read_options);
    skip_to(*reader, range.first);
  });
  const std::uint64_t widest = (range.count + ranks - 1) / ranks;  // the most records a rank reads
  const std::uint64_t rounds = (widest + chunk - 1) / chunk;
  Progress progress("sorting", "points", range.end - range.first, options.progress && root);
  std::uint64_t received = 0;
  std::vector<std::size_t> slot(ranks);
  for (std::uint64_t round = 0; round < rounds; ++round) {
    std::vector<std::uint64_t> counts(ranks, 0);
    std::size_t got = 0;
    together(comm, [&] {
      const std::uint64_t at = range.first + round * chunk;
      got = at < range.end ? std::size_t(std::min<std::uint64_t>(chunk, range.end - at)) : 0;
      read_exactly(*reader, xyz.data(), got);
      std::vector<std::uint32_t> to(got);
      for (std::size_t i = 0; i < got; ++i)
        ++counts[to[i] = std::uint32_t(rank_of(splitters, key_of(&xyz[3 * i], axis)))];
      for (std::size_t r = 0, s = 0; r < ranks; ++r) slot[r] = s, s += counts[r];
      for (std::size_t i = 0; i < got; ++i) {
        send[slot[to[i]]++].set(&xyz[3 * i], at + i);  // exact: R holds the input's own values
      }
      check_interrupted();
    });
    const std::vector<std::uint64_t> incoming = comm.all_to_all(counts);
    std::uint64_t total = 0;
    for (std::uint64_t n : incoming) total += n;
    together(comm, [&] {
      if (run.size() + total > capacity) flush();
    });
    const std::size_t at = run.size();
    run.resize(at + std::size_t(total));  // within the capacity reserved: no reallocation
    // Received as records R packed at the start of the new slots, then widened in
    // place, last first: record i lies at or before slot i, so widening slot i only
    // overwrites records already widened.
    std::byte* landing = reinterpret_cast<std::byte*>(run.data() + at);
    comm.exchange(send.data(), counts, landing, incoming, sizeof(R));
    for (std::size_t i = std::size_t(total); i-- > 0;) {
      R record;
      std::memcpy(&record, landing + i * sizeof(R), sizeof(R));
      SortedPoint& p = run[at + i];
      record.xyz(p.xyz);
      p.original = record.original();
    }
    received += total;
    progress.add(got);
  }
  together(comm, [&] { flush(); });
  reader.reset();
  progress.finish();

  // Where this rank writes: after the ranks before it, as if no duplicate were merged.
  const std::vector<std::uint64_t> receipts = comm.all_gather(received);
  std::string lead_text;
  if (root) lead_text = std::to_string(payload_offset_before_merge(target.header, result));
  const std::uint64_t lead = std::stoull(comm.broadcast(lead_text, 0));
  std::uint64_t offset = lead;
  for (int r = 0; r < comm.rank(); ++r) offset += receipts[std::size_t(r)] * sizeof(R);
  together(comm, [&] {
    sorter.set_give_back_runs(true);
    PartSink sink(out, offset);
    sort_detail::merge_runs_into<R>(sorter, hull_originals, sink, /*sync=*/true, options.progress && root, received,
                                    result);
  });
  return offset;
}

}  // namespace

bool sorts_by_ranges(const std::string& input, const io::PointReadOptions& read_options) {
  return io::open_points(input, read_options)->count().has_value();
}

namespace {

// Reads this rank's K-th of the input once: its bounding box, whether it is float32,
// and a sample of its points for the splitters.
struct RankScan {
  InputRange range;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  bool float32 = false;
  std::vector<double> sample;  // xyz of sampled points
};

RankScan scan_rank_range(Communicator& comm, const std::string& input, const io::PointReadOptions& read_options,
                         const PointSortOptions& options) {
  const std::size_t ranks = std::size_t(comm.size()), me = std::size_t(comm.rank());
  const bool root = me == 0;
  RankScan scan;
  InputRange& range = scan.range;
  double* lo = scan.lo;
  double* hi = scan.hi;
  bool& float32 = scan.float32;
  std::vector<double>& sample = scan.sample;
  together(comm, [&] {
    auto reader = io::open_points(input, read_options);
    if (!reader->count()) throw std::logic_error("sort_points_distributed: an input without a count");
    range.count = *reader->count();
    range.first = std::uint64_t((unsigned __int128)range.count * me / ranks);
    range.end = std::uint64_t((unsigned __int128)range.count * (me + 1) / ranks);
    skip_to(*reader, range.first);
    const std::uint64_t n = range.end - range.first;
    const std::uint64_t step = std::max<std::uint64_t>(1, n / kSamplesPerRank);
    std::vector<double> chunk(3 * kReadChunk);
    Progress progress("reading", "points", n, options.progress && root);
    for (std::uint64_t done = 0; done < n;) {
      const std::size_t got = std::size_t(std::min<std::uint64_t>(kReadChunk, n - done));
      read_exactly(*reader, chunk.data(), got);
      for (std::size_t i = 0; i < got; ++i) {
        for (int k = 0; k < 3; ++k) {
          lo[k] = std::min(lo[k], chunk[3 * i + k]);
          hi[k] = std::max(hi[k], chunk[3 * i + k]);
        }
        if ((done + i) % step == 0 && sample.size() < 3 * kSamplesPerRank)
          sample.insert(sample.end(), &chunk[3 * i], &chunk[3 * i] + 3);
      }
      done += got;
      progress.add(got);
      check_interrupted();
    }
    progress.finish();
    float32 = reader->float32_input();
  });
  return scan;
}

// Rank 0 cuts the ranks' sorted samples into K key ranges of about equal counts.
std::vector<Key> choose_splitters(Communicator& comm, const RankScan& scan, int axis) {
  const std::size_t ranks = std::size_t(comm.size());
  const bool root = comm.rank() == 0;
  std::vector<Key> keys;
  for (std::size_t i = 0; i + 3 <= scan.sample.size(); i += 3) keys.push_back(key_of(&scan.sample[i], axis));
  const std::vector<std::string> samples = comm.gather(to_bytes(keys), 0);
  std::string chosen;
  if (root) {
    std::vector<Key> all;
    for (const std::string& s : samples) {
      const std::vector<Key> theirs = from_bytes<Key>(s);
      all.insert(all.end(), theirs.begin(), theirs.end());
    }
    std::sort(all.begin(), all.end(), key_less);
    std::vector<Key> splitters;
    for (std::size_t r = 1; r < ranks && !all.empty(); ++r) splitters.push_back(all[all.size() * r / ranks]);
    chosen = to_bytes(splitters);
  }
  return from_bytes<Key>(comm.broadcast(chosen, 0));
}

// The ranks' parts into one points section: each part moved to where its labels
// begin, then rank 0 writes the section's lead and trailer (the CRC of the parts
// combined) and gathers the hull's labels.
SortedPoints close_parts(Communicator& comm, io::OutputPart* out, const DistributedSortTarget& target,
                         const SortedPoints& result, std::uint64_t written_at) {
  const std::size_t ranks = std::size_t(comm.size()), me = std::size_t(comm.rank());
  const bool root = me == 0;
  const std::size_t record_bytes = result.layout.bytes();
  const std::vector<std::uint64_t> counts = comm.all_gather(result.count);
  const std::vector<std::uint64_t> duplicates = comm.all_gather(result.duplicates);
  const std::vector<std::uint64_t> crcs = comm.all_gather(result.crc32c);
  const std::vector<std::uint64_t> runs = comm.all_gather(result.runs);
  const std::vector<std::uint64_t> offsets = comm.all_gather(written_at);
  std::uint64_t first_label = 0;
  for (std::size_t r = 0; r < me; ++r) first_label += counts[r];
  std::vector<std::uint64_t> hull = result.hull_labels;
  for (std::uint64_t& label : hull) label += first_label;
  const std::vector<std::string> hulls = comm.gather(to_bytes(hull), 0);
  SortedPoints whole = result;
  whole.count = whole.duplicates = whole.runs = 0;
  for (std::size_t r = 0; r < ranks; ++r) {
    whole.count += counts[r];
    whole.duplicates += duplicates[r];
    whole.runs += runs[r];
  }
  std::string lead_text;
  if (root) lead_text = std::to_string(points_lead(target.header, whole).size());
  const std::uint64_t lead = std::stoull(comm.broadcast(lead_text, 0));
  // Each part's move: the place its labels begin at, against where it was written.
  std::vector<std::uint64_t> place(ranks);
  bool moves = false;
  for (std::size_t r = 0, label = 0; r < ranks; label += counts[r], ++r) {
    place[r] = lead + label * record_bytes;
    moves = moves || place[r] != offsets[r];
  }
  if (moves) {
    auto move_mine = [&] {
      move_file_bytes(out->fd(), target.partial, offsets[me], place[me], counts[me] * record_bytes);
      out->sync();
    };
    // Towards the start in rank order, then towards the end in reverse order: a
    // part's place overlaps only parts that have moved already (see the header).
    for (std::size_t r = 0; r < ranks; ++r)
      if (place[r] < offsets[r])
        together(comm, [&] {
          if (r == me) move_mine();
        });
    for (std::size_t r = ranks; r-- > 0;)
      if (place[r] > offsets[r])
        together(comm, [&] {
          if (r == me) move_mine();
        });
  }
  together(comm, [&] {
    if (!root) return;
    std::uint32_t crc = 0;
    for (std::size_t r = 0; r < ranks; ++r)
      crc = io::crc32c_combine(crc, std::uint32_t(crcs[r]), counts[r] * record_bytes);
    const std::vector<std::uint8_t> lead_bytes = points_lead(target.header, whole);
    std::uint8_t trailer[4];
    io::put_u32(trailer, crc);
    out->write_at(lead_bytes.data(), lead_bytes.size(), 0);
    out->write_at(trailer, sizeof trailer, lead + whole.count * record_bytes);
    out->sync();
    whole.path = target.partial;
    whole.offset = lead;
    whole.crc32c = crc;
    whole.hull_labels.clear();
    for (const std::string& h : hulls) {
      const std::vector<std::uint64_t> theirs = from_bytes<std::uint64_t>(h);
      whole.hull_labels.insert(whole.hull_labels.end(), theirs.begin(), theirs.end());
    }
  });
  return whole;
}

}  // namespace

SortedPoints sort_points_distributed(Communicator& comm, const std::string& input,
                                     const io::PointReadOptions& read_options, const PointSortOptions& options,
                                     const std::string& dir, const std::string& runs_name,
                                     const DistributedSortTarget& target) {
  SortedPoints result;
  auto t0 = Clock::now();

  // ---- scan: this rank's records for the bounding box and a sample of keys ----
  const RankScan scan = scan_rank_range(comm, input, read_options, options);
  const InputRange& range = scan.range;
  const double* lo = scan.lo;
  const double* hi = scan.hi;
  const bool float32 = scan.float32;
  SortProgress scanned;
  scanned.scanned = true;
  scanned.input_count = range.count;
  scanned.float32 = true;
  for (std::uint64_t f : comm.all_gather(float32)) scanned.float32 = scanned.float32 && f != 0;
  double extent[3];
  for (int k = 0; k < 3; ++k) {
    scanned.bbox_min[k] = INFINITY, scanned.bbox_max[k] = -INFINITY;
    for (std::uint64_t v : comm.all_gather(std::bit_cast<std::uint64_t>(lo[k])))
      scanned.bbox_min[k] = std::min(scanned.bbox_min[k], std::bit_cast<double>(v));
    for (std::uint64_t v : comm.all_gather(std::bit_cast<std::uint64_t>(hi[k])))
      scanned.bbox_max[k] = std::max(scanned.bbox_max[k], std::bit_cast<double>(v));
    extent[k] = scanned.bbox_max[k] - scanned.bbox_min[k];
    result.bbox_min[k] = scanned.bbox_min[k], result.bbox_max[k] = scanned.bbox_max[k];
  }
  scanned.axis = int(std::max_element(extent, extent + 3) - extent);
  result.input_count = range.count;
  result.axis = scanned.axis;
  result.layout = RecordLayout::for_input(scanned.float32, range.count);
  result.seconds_scan = since(t0);
  // Every rank the same answer (the same figures): rank 0's line if refused.
  together(comm, [&] {
    if (options.on_scanned) options.on_scanned(scanned);
  });

  // ---- splitters: rank 0 cuts the sorted sample into K ranges ----
  const std::vector<Key> splitters = choose_splitters(comm, scan, result.axis);

  // ---- exchange and merge, each rank into its place ----
  t0 = Clock::now();
  std::optional<io::OutputPart> out;
  together(comm, [&] { out.emplace(target.partial, target.identity); });
  std::uint64_t written_at = 0;
  with_record(result.layout, [&](auto r) {
    written_at = exchange_and_merge<decltype(r)>(comm, input, read_options, options, dir, runs_name, range, splitters,
                                                 *out, target, result);
  });

  // ---- close: the ranks' parts into one section ----
  SortedPoints whole = close_parts(comm, &*out, target, result, written_at);
  whole.seconds_runs = since(t0);  // the exchange, the merge and the close
  return whole;
}

}  // namespace tetstream::pipeline
