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

}  // namespace tetstream::pipeline
