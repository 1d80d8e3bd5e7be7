#include "pipeline/field/output.hpp"

#include "core/compiler.hpp"
#include "pipeline/files/temp_files.hpp"

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
    if (f32_)
      w_.write(f_.data(), f_.size() * sizeof(float)), f_.clear();
    else
      w_.write(d_.data(), d_.size() * sizeof(double)), d_.clear();
  }
  bool f32_;
  io::NpyArrayWriter w_;
  std::vector<float> f_;
  std::vector<double> d_;
};

}  // namespace

PointOrder::PointOrder(const FieldOptions& options, std::uint64_t original_end, std::uint64_t memory_bytes,
                       ExternalSortOptions sort)
    : end_(original_end) {
  // The density (and the grid's densities with --mass) needs the star's volume, the
  // Voronoi output the cell's; the label only for the grid's way back to label order.
  const bool volume = options.density || options.grid_wanted(), voronoi = options.voronoi;
  const bool label = options.grid_wanted() && !options.mass.empty();
  const std::uint64_t per_index = 1 + 8 * (std::uint64_t(volume) + std::uint64_t(voronoi) + std::uint64_t(label));
  if (original_end > memory_bytes / per_index) {
    sorter_ = std::make_unique<ExternalSorter<PointRecord, ByOriginal>>(std::move(sort));
    return;
  }
  // Written once here: a fresh mapping's pages are placed on huge pages as they fault
  // (the placement below is at random, and would miss the TLB on every point with
  // small pages), and every flag starts clear (an index never added is a duplicate
  // `run` merged).
  flags_.assign(std::size_t(original_end), 0);
  if (volume) volume_.assign(std::size_t(original_end), 0.0);
  if (voronoi) voronoi_.assign(std::size_t(original_end), 0.0);
  if (label) label_.assign(std::size_t(original_end), 0);
}

void PointOrder::add(std::span<const FinalPoint> points) {
  if (sorter_) {
    for (const FinalPoint& p : points) sorter_->push({p.original, p.label, p.volume, p.voronoi, p.hull ? 1u : 0u});
    return;
  }
  // Label order is not input order: every slot is a cache miss, asked for ahead.
  constexpr std::size_t kAhead = 16;
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (k + kAhead < points.size()) {
      const std::size_t j = std::size_t(points[k + kAhead].original);
      TS_PREFETCH(&flags_[j]);
      if (!volume_.empty()) TS_PREFETCH(&volume_[j]);
      if (!voronoi_.empty()) TS_PREFETCH(&voronoi_[j]);
    }
    const FinalPoint& p = points[k];
    const std::size_t i = std::size_t(p.original);
    flags_[i] = std::uint8_t(kPresent | (p.hull ? kHull : 0));
    if (!volume_.empty()) volume_[i] = p.volume;
    if (!voronoi_.empty()) voronoi_[i] = p.voronoi;
    if (!label_.empty()) label_[i] = p.label;
  }
}

void PointOrder::merge(const std::function<void(std::span<const PointRecord>)>& visit) {
  if (sorter_) {
    sorter_->merge(visit);
    sorter_.reset();
    return;
  }
  // The records the sort would give, in the same order (only the fields asked for set).
  std::vector<PointRecord> batch;
  batch.reserve(std::size_t(1) << 16);
  for (std::size_t i = 0; i < end_; ++i) {
    if (!(flags_[i] & kPresent)) continue;
    batch.push_back({i, label_.empty() ? 0 : label_[i], volume_.empty() ? 0.0 : volume_[i],
                     voronoi_.empty() ? 0.0 : voronoi_[i], (flags_[i] & kHull) ? 1u : 0u});
    if (batch.size() == batch.capacity()) visit(batch), batch.clear();
  }
  if (!batch.empty()) visit(batch);
  flags_ = {}, volume_ = {}, voronoi_ = {}, label_ = {};
}

std::string field_path(const FieldOptions& options, const std::string& what) {
  return options.output + "." + what + ".npy";
}

void write_point_fields(PointOrder& records, const FieldOptions& options, std::uint64_t point_count,
                        io::ScalarFileReader* masses, const std::function<void(std::uint64_t, double)>& by_label,
                        FieldSummary& summary) {
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
    throw std::logic_error("field: " + std::to_string(seen) + " points ordered, expected " +
                           std::to_string(point_count));
  if (density) density->commit(), summary.files.push_back({"density", field_path(options, "density")});
  if (voronoi) voronoi->commit(), summary.files.push_back({"voronoi", field_path(options, "voronoi")});
}

}  // namespace tetstream::pipeline
