#include "pipeline/field_output.hpp"

#include "pipeline/temp_files.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace tetstream::pipeline {
namespace {

// A .npy column written in the job's dtype, buffered.
class Column {
 public:
  Column(const std::string& path, FieldType type, std::uint64_t n)
      : f32_(type == FieldType::kFloat32), w_(path, f32_ ? "<f4" : "<f8", {n}) {}
  void add(double v) {
    if (f32_) {
      f_.push_back(float(v));
      if (f_.size() == kBuffer) flush();
    } else {
      d_.push_back(v);
      if (d_.size() == kBuffer) flush();
    }
  }
  void commit() {
    flush();
    w_.commit();
  }

 private:
  static constexpr std::size_t kBuffer = 1 << 16;
  void flush() {
    if (f32_) w_.write(f_.data(), f_.size() * sizeof(float)), f_.clear();
    else w_.write(d_.data(), d_.size() * sizeof(double)), d_.clear();
  }
  bool f32_;
  io::NpyArrayWriter w_;
  std::vector<float> f_;
  std::vector<double> d_;
};

// An int64 .npy column, buffered.
class IntColumn {
 public:
  IntColumn(const std::string& path, std::uint64_t n) : w_(path, "<i8", {n}) {}
  void add(std::uint64_t v) {
    b_.push_back(std::int64_t(v));
    if (b_.size() == (1 << 16)) flush();
  }
  void commit() {
    flush();
    w_.commit();
  }

 private:
  void flush() {
    w_.write(b_.data(), b_.size() * sizeof(std::int64_t));
    b_.clear();
  }
  io::NpyArrayWriter w_;
  std::vector<std::int64_t> b_;
};

}  // namespace

std::string field_path(const FieldOptions& options, const std::string& what) {
  return options.output + "." + what + ".npy";
}

void write_point_fields(ExternalSorter<PointRecord, ByOriginal>& records, const FieldOptions& options,
                        std::uint64_t point_count, io::ScalarFileReader* masses,
                        const std::function<void(std::uint64_t, double)>& by_label, FieldSummary& summary) {
  std::optional<Column> density, voronoi;
  if (options.density) density.emplace(field_path(options, "density"), options.dtype, point_count);
  if (options.voronoi) voronoi.emplace(field_path(options, "voronoi"), options.dtype, point_count);
  std::uint64_t seen = 0;
  records.merge([&](std::span<const PointRecord> batch) {
    for (const PointRecord& r : batch) {
      const double m = masses ? masses->at(r.original) : 1.0;
      summary.total_mass += m;
      const double rho = dtfe_density(m, r.volume, r.hull != 0, options.hull);
      if (density) density->add(rho);
      if (voronoi) voronoi->add(r.hull ? std::numeric_limits<double>::infinity() : r.voronoi);
      if (by_label) by_label(r.label, rho);
      ++seen;
    }
  });
  if (seen != point_count)
    throw std::logic_error("field: " + std::to_string(seen) + " points ordered, expected " + std::to_string(point_count));
  if (density) density->commit(), summary.files.push_back({"density", field_path(options, "density")});
  if (voronoi) voronoi->commit(), summary.files.push_back({"voronoi", field_path(options, "voronoi")});
}

void write_neighbours(ExternalSorter<NeighbourRecord, ByPair>& records, const FieldOptions& options,
                      std::uint64_t point_count, const TempDir& tmp, FieldSummary& summary) {
  // The entries' count is known at the end only, and .npy states it up front: the
  // indices go to a scratch file first and are copied behind the header after.
  IntColumn offsets(field_path(options, "neighbours.offsets"), point_count + 1);
  const std::string scratch = tmp.path("neighbour-indices.i64");
  std::uint64_t at = 0, rows = 0;
  {
    BinaryFile out(scratch, "wb");
    std::vector<std::int64_t> buf;
    NeighbourRecord last{kRowMarker, kRowMarker};
    offsets.add(0);
    records.merge([&](std::span<const NeighbourRecord> batch) {
      for (const NeighbourRecord& r : batch) {
        if (r.other == kRowMarker) {  // sorts after the row's entries: the row is complete
          offsets.add(at);
          ++rows;
        } else if (r.original != last.original || r.other != last.other) {  // copies of an edge are adjacent
          buf.push_back(std::int64_t(r.other));
          ++at;
          if (buf.size() == (1 << 16)) out.write(buf.data(), sizeof(std::int64_t), buf.size()), buf.clear();
        }
        last = r;
      }
    });
    out.write(buf.data(), sizeof(std::int64_t), buf.size());
    out.close();
  }
  if (rows != point_count)
    throw std::logic_error("field: " + std::to_string(rows) + " neighbour rows, expected " + std::to_string(point_count));
  io::NpyArrayWriter indices(field_path(options, "neighbours.indices"), "<i8", {at});
  {
    BinaryFile in(scratch, "rb");
    std::vector<char> buf(std::size_t(8) << 20);
    while (const std::size_t got = in.read(buf.data(), 1, buf.size())) indices.write(buf.data(), got);
  }
  remove_file(scratch);
  offsets.commit();
  indices.commit();
  summary.neighbour_entries = at;
  summary.files.push_back({"neighbours.offsets", field_path(options, "neighbours.offsets")});
  summary.files.push_back({"neighbours.indices", field_path(options, "neighbours.indices")});
}

}  // namespace tetstream::pipeline
