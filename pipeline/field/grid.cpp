#include "pipeline/field/grid.hpp"

#include "core/error.hpp"
#include "io/npy.hpp"
#include "io/output_file.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/field/geometry.hpp"
#include "pipeline/field/output.hpp"
#include "pipeline/field/points.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/files/temp_files.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <fcntl.h>
#include <map>
#include <unistd.h>
#include <unordered_map>
#include <limits>
#include <vector>

namespace tetstream::pipeline {
namespace {

struct GridRecord {
  std::uint64_t index;
  double value;
};
struct ByIndex {
  bool operator()(const GridRecord& a, const GridRecord& b) const { return a.index < b.index; }
};

class GridSampler {
 public:
  GridSampler(const io::TetReader& reader, const BatchPlan& plan, const GridSpec& grid, int axis,
              const std::string& rho_path, const FieldOptions& options, std::uint64_t budget, const std::string& tmpdir)
      : reader_(reader),
        plan_(plan),
        g_(grid),
        axis_(axis),
        u_((axis + 1) % 3 < (axis + 2) % 3 ? (axis + 1) % 3 : (axis + 2) % 3),
        w_(3 - axis - u_),
        f32_(options.dtype == FieldType::kFloat32),
        points_(reader, plan.ring_labels),
        rho_(plan.ring_labels),
        rho_file_(rho_path, "rb"),
        out_(options.output + ".grid.npy", f32_ ? "<f4" : "<f8", {grid.n[0], grid.n[1], grid.n[2]}),
        rho_path_(rho_path) {
    plane_size_ = g_.n[std::size_t(u_)] * g_.n[std::size_t(w_)];
    max_planes_ = std::max<std::uint64_t>(1, budget / (plane_size_ * sizeof(double)));
    points_.check_sorted_along(axis, io::label_brick(reader));
    // The centres' coordinates once (the same expression as GridSpec::centre, so the
    // same bits): computing them per candidate cost a division each.
    for (int k = 0; k < 3; ++k)
      for (std::uint64_t i = 0; i < g_.n[std::size_t(k)]; ++i) centres_[std::size_t(k)].push_back(g_.centre(k, i));
    if (axis_ != 0) {
      ExternalSortOptions so;
      so.memory_bytes = std::max<std::uint64_t>(budget / 2, 16 << 20);
      so.dir = tmpdir;
      so.name = "grid";
      sorter_ = std::make_unique<ExternalSorter<GridRecord, ByIndex>>(so);
    }
  }

  ~GridSampler() {
    if (rho_fd_ >= 0) ::close(rho_fd_);
  }

  GridStats run(Progress* progress) {
    const std::uint64_t na = g_.n[std::size_t(axis_)];
    for (const FrameBatch& b : plan_.batches) {
      check_interrupted();
      points_.advance(b.lo, [this](std::uint64_t l) {
        double r;
        if (rho_file_.read(&r, sizeof r, 1) != 1) throw IoError("field: the density file ended early");
        rho_[l] = r;
      });
      batch_.decode(reader_, b);
      points_.fetch_far(batch_);
      fetch_far_densities();
      // Planes up to the one past the batch's dense tets (a tet is no further along the
      // axis than its vertices); grid points of the rare tets that reach far labels,
      // beyond the planes held, wait in a map for their plane.
      grow_to(std::min<std::uint64_t>(na, plane_at_or_below(dense_reach()) + 2));
      sample_batch();
      for (std::size_t k = b.first_frame; k < b.end_frame; ++k) reader_.release_frame_pages(k);
      if (b.retire_below < reader_.point_count()) retire_below(floor_from(b.retire_below));
      if (progress) progress->add(b.tets);
    }
    retire_below(std::numeric_limits<double>::infinity());
    while (emitted_ < na) emit_nan_plane();
    if (sorter_) {
      sorter_->merge([this](std::span<const GridRecord> batch) {
        for (const GridRecord& r : batch) put(r.value);
      });
    }
    flush();
    out_.commit();
    return stats_;
  }

 private:
  // The last plane index whose centre is <= x (or 0 when none), clamped to the grid.
  std::uint64_t plane_at_or_below(double x) const {
    const double t = (x - g_.lo[std::size_t(axis_)]) / (g_.hi[std::size_t(axis_)] - g_.lo[std::size_t(axis_)]) *
                         double(g_.n[std::size_t(axis_)]) -
                     0.5;
    if (!(t > 0)) return 0;
    return std::min<std::uint64_t>(g_.n[std::size_t(axis_)] - 1, std::uint64_t(t));
  }

  void grow_to(std::uint64_t end) {
    while (first_plane_ + planes_.size() < end) {
      if (planes_.size() + 1 > max_planes_)
        throw UsageError("field: the grid's slab window needs more than " + std::to_string(max_planes_) +
                         " planes of " + human_bytes(double(plane_size_ * sizeof(double))) +
                         ": raise --memory or use a coarser grid");
      planes_.emplace_back(plane_size_, std::numeric_limits<double>::quiet_NaN());
      stats_.peak_planes = std::max<std::uint64_t>(stats_.peak_planes, planes_.size());
    }
  }

  // Index range [first, last] of the grid centres along `axis` within [a, b]: the
  // exact condition is (a - lo) s - 1/2 <= i <= (b - lo) s - 1/2; the bounds are widened
  // by far more than the rounding of them and of the centres' coordinates (a few ulps
  // of the coordinates, in cells), so no centre inside is missed (the exact test
  // decides the rest). The sampling axis starts at the first plane held. Empty when
  // first > last.
  void range(int axis, double a, double b, std::int64_t& first, std::int64_t& last) const {
    const std::size_t k = std::size_t(axis);
    const double scale = double(g_.n[k]) / (g_.hi[k] - g_.lo[k]);
    const double slack =
        1e-9 + 1e-14 * (std::fabs(a) + std::fabs(b) + std::fabs(g_.lo[k]) + std::fabs(g_.hi[k])) * scale;
    first = std::int64_t(std::ceil(std::max(-1.0, (a - g_.lo[k]) * scale - 0.5 - slack)));
    last = std::int64_t(std::floor(std::min(double(g_.n[k]), (b - g_.lo[k]) * scale - 0.5 + slack)));
    std::int64_t lo = 0, hi = std::int64_t(g_.n[k]) - 1;
    if (axis == axis_) lo = std::int64_t(first_plane_);  // planes before it are final: no tet reaches them
    first = std::max(first, lo);
    last = std::min(last, hi);
  }

  void sample_batch() {
    const std::int64_t n = std::int64_t(batch_.tets());
    std::uint64_t inside = 0;
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : inside)
    for (std::int64_t t = 0; t < n; ++t) {
      const std::uint64_t* q = batch_.tet(std::size_t(t));
      const double* p[4] = {points_.xyz(q[0]), points_.xyz(q[1]), points_.xyz(q[2]), points_.xyz(q[3])};
      std::int64_t r0[3], r1[3];
      bool empty = false;
      for (int k = 0; k < 3; ++k) {
        double a = p[0][k], b = p[0][k];
        for (int v = 1; v < 4; ++v) a = std::min(a, p[v][k]), b = std::max(b, p[v][k]);
        range(k, a, b, r0[k], r1[k]);
        empty = empty || r0[k] > r1[k];
      }
      // No centre in the bounding box (a small tet between grid lines, or one below
      // the planes held): neither the locator's planes nor the densities are needed.
      if (empty) continue;
      const double f[4] = {rho(q[0]), rho(q[1]), rho(q[2]), rho(q[3])};
      const TetLocator locate(p[0], p[1], p[2], p[3]);
      for (std::int64_t i = r0[axis_]; i <= r1[axis_]; ++i)
        for (std::int64_t j = r0[u_]; j <= r1[u_]; ++j)
          for (std::int64_t k = r0[w_]; k <= r1[w_]; ++k) {
            double g[3];
            g[axis_] = centres_[std::size_t(axis_)][std::size_t(i)];
            g[u_] = centres_[std::size_t(u_)][std::size_t(j)];
            g[w_] = centres_[std::size_t(w_)][std::size_t(k)];
            if (!locate.contains(g)) continue;
            const double v = tet_interpolate(p, f, g);
            const std::size_t at = std::size_t(j) * g_.n[std::size_t(w_)] + std::size_t(k);
            if (std::uint64_t(i) < first_plane_ + planes_.size()) {
              planes_[std::size_t(std::uint64_t(i) - first_plane_)][at] = v;
            } else {
#pragma omp critical(field_grid_far)
              far_values_[{std::uint64_t(i), at}] = v;
            }
            ++inside;
          }
    }
    stats_.inside += inside;
  }

  // The largest axis coordinate of the batch's tets whose labels are all dense.
  double dense_reach() const {
    double top = -std::numeric_limits<double>::infinity();
    for (std::size_t f = 0; f < batch_.frames(); ++f) {
      const std::vector<std::uint64_t>& t = batch_.frame(f);
      for (std::size_t i = 0; i < t.size(); i += 4) {
        if (!points_.dense(t[i + 1]) || !points_.dense(t[i + 2]) || !points_.dense(t[i + 3])) continue;
        for (int v = 0; v < 4; ++v) top = std::max(top, points_.xyz(t[i + std::size_t(v)])[axis_]);
      }
    }
    return top;
  }

  // Densities of the far labels, read one by one from the file by label.
  void fetch_far_densities() {
    if (points_.dense_end() == reader_.point_count()) return;
    if (rho_fd_ < 0) rho_fd_ = ::open(rho_path_.c_str(), O_RDONLY | O_CLOEXEC);
    if (rho_fd_ < 0) throw IoError(rho_path_ + ": cannot open");
    std::erase_if(far_rho_, [this](const auto& kv) { return points_.dense(kv.first); });
    for (std::size_t f = 0; f < batch_.frames(); ++f)
      for (const std::uint64_t l : batch_.frame(f)) {
        if (points_.dense(l) || far_rho_.count(l)) continue;
        double r;
        if (!io::pread_exactly(rho_fd_, &r, sizeof r, l * sizeof r)) throw IoError(rho_path_ + ": read failed");
        far_rho_.emplace(l, r);
      }
  }
  double rho(std::uint64_t l) const { return points_.dense(l) ? rho_[l] : far_rho_.find(l)->second; }

  // A coordinate along the axis below which no tet of smallest label `label` or above
  // reaches: their vertices are of that label or above. In version 1 the label's own
  // point; in version 2 the top of the bricks before its brick (a brick's labels are in
  // no order along the axis), so the planes retire a brick later.
  double floor_from(std::uint64_t label) const {
    if (io::label_brick(reader_) > 1) return points_.axis_floor(label);
    double next[3];
    reader_.read_points(label, 1, next, nullptr);
    return next[axis_];
  }

  // Planes whose centre lies below x are final.
  void retire_below(double x) {
    while (!planes_.empty() && g_.centre(axis_, first_plane_) < x) {
      emit(std::move(planes_.front()));
      planes_.pop_front();
      ++first_plane_;
    }
    if (planes_.empty()) {
      // Nothing held: the planes below x that no tet reached are NaN.
      while (emitted_ < g_.n[std::size_t(axis_)] && g_.centre(axis_, emitted_) < x) emit_nan_plane();
      first_plane_ = emitted_;
    }
  }

  void emit_nan_plane() { emit(std::vector<double>(plane_size_, std::numeric_limits<double>::quiet_NaN())); }

  void emit(std::vector<double> plane) {
    const std::uint64_t i = emitted_++;
    // Values from tets that reached this plane before it was held.
    for (auto it = far_values_.lower_bound({i, 0}); it != far_values_.end() && it->first.first == i;)
      plane[it->first.second] = it->second, it = far_values_.erase(it);
    if (!sorter_) {
      for (const double v : plane) put(v);
      return;
    }
    // C order (x, y, z): place the plane's (u, w) values.
    for (std::uint64_t j = 0; j < g_.n[std::size_t(u_)]; ++j)
      for (std::uint64_t k = 0; k < g_.n[std::size_t(w_)]; ++k) {
        std::uint64_t c[3];
        c[axis_] = i, c[u_] = j, c[w_] = k;
        sorter_->push({(c[0] * g_.n[1] + c[1]) * g_.n[2] + c[2], plane[j * g_.n[std::size_t(w_)] + k]});
      }
  }

  void put(double v) {
    if (f32_)
      buf32_.push_back(float(v));
    else
      buf64_.push_back(v);
    if (buf32_.size() + buf64_.size() >= (1 << 16)) flush();
  }
  void flush() {
    out_.write(buf32_.data(), buf32_.size() * sizeof(float));
    out_.write(buf64_.data(), buf64_.size() * sizeof(double));
    buf32_.clear();
    buf64_.clear();
  }

  const io::TetReader& reader_;
  const BatchPlan& plan_;
  GridSpec g_;
  int axis_, u_, w_;
  bool f32_;
  WindowPoints points_;
  LabelRing<double> rho_;
  BinaryFile rho_file_;
  io::NpyArrayWriter out_;
  DecodedBatch batch_;
  std::deque<std::vector<double>> planes_;  // planes first_plane_ .. first_plane_ + size - 1
  std::uint64_t first_plane_ = 0, emitted_ = 0;
  std::uint64_t plane_size_ = 0, max_planes_ = 0;
  std::array<std::vector<double>, 3> centres_;  // centre coordinates along each axis
  std::unique_ptr<ExternalSorter<GridRecord, ByIndex>> sorter_;
  std::vector<float> buf32_;
  std::vector<double> buf64_;
  std::string rho_path_;
  int rho_fd_ = -1;
  std::unordered_map<std::uint64_t, double> far_rho_;
  std::map<std::pair<std::uint64_t, std::uint64_t>, double> far_values_;  // (plane, offset) -> value
  GridStats stats_;
};

}  // namespace

GridStats sample_grid(const io::TetReader& reader, const BatchPlan& plan, const GridSpec& grid, int axis,
                      const std::string& rho_path, const FieldOptions& options, std::uint64_t plane_bytes_budget,
                      const std::string& tmpdir, Progress* progress) {
  return GridSampler(reader, plan, grid, axis, rho_path, options, plane_bytes_budget, tmpdir).run(progress);
}

}  // namespace tetstream::pipeline
