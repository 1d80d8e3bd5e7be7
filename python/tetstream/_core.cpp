// tetstream._core: the compiled half of the Python package (python/tetstream/__init__.py
// is the public face, with the docstrings and type hints; docs/python.md).
//
//   delaunay(points, index_dtype)  the in-core kernel (core::Delaunay) on an (N, 3) array
//   run(input, output, options)    the out-of-core job (pipeline::run_job), its --json summary
//   Reader(path)                   a .tets container (io::TetReader): points, frames, tets
//   verify(path, ...)              pipeline::verify_file, its --json report
//   field(...), field_memory(...)  pipeline::compute_fields over a container; the same
//                                  sums over an in-memory triangulation
//   convert, expand_inputs, read_points   io::export_mesh, the CLI's globs, a point file
//   find_simplex, ...              scipy.spatial.Delaunay's queries (_geometry.cpp)
//
// Every long computation runs with the GIL released. Arrays handed to Python are not
// copied: each owns a heap buffer through a capsule (its .base) that frees it.
// Exceptions: tetstream's InputError/UsageError -> ValueError subclasses, IoError ->
// an OSError subclass, Interrupted -> KeyboardInterrupt (see register_exceptions).
// Log lines (spdlog) are queued and handed to a Python callable on the calling thread
// (the package passes them to `logging`), never written to file descriptor 2.
#include "core/delaunay.hpp"
#include "core/error.hpp"
#include "core/huge_pages.hpp"
#include "core/spatial_sort.hpp"
#include "io/mesh_export.hpp"
#include "io/point_format.hpp"
#include "io/point_reader.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/field/field.hpp"
#include "pipeline/field/geometry.hpp"
#include "io/output_file.hpp"
#include "pipeline/run/run.hpp"
#include "io/tet_container.hpp"
#include "io/tet_periodic.hpp"
#include "pipeline/periodic/periodic.hpp"
#include "pipeline/periodic/tet_records.hpp"
#include "pipeline/run/summary_json.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/verify/verify.hpp"
#include "python/tetstream/_geometry.hpp"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <omp.h>
#include <sys/mman.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <optional>
#include <span>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <exception>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace py = pybind11;
using namespace tetstream;

namespace {

// ---- arrays that own their buffer (no copy on the way to Python) ----

// An uninitialised heap buffer of n T's; handed to Python by to_array().
// Large ones ask for transparent huge pages before their first touch: filling a fresh
// 200 MiB array costs ~50,000 page faults with 4 KiB pages, ~100 with 2 MiB ones.
template <class T>
struct Buffer {
  std::unique_ptr<T[]> data;
  std::size_t size = 0;
  explicit Buffer(std::size_t n = 0) : data(n ? new T[n] : nullptr), size(n) {
    if (n * sizeof(T) >= (std::size_t(4) << 20)) core::advise_huge_pages(data.get(), n * sizeof(T));
  }
  T* get() { return data.get(); }
};

// A C-contiguous array of shape `shape` over the buffer, which the array's base (a
// capsule) now owns. Needs the GIL.
template <class T>
py::array_t<T> to_array(Buffer<T>&& b, std::vector<py::ssize_t> shape) {
  T* p = b.data.release();
  if (p == nullptr) p = new T[1];  // numpy wants a pointer even for an empty array
  py::capsule owner(p, [](void* q) { delete[] static_cast<T*>(q); });
  return py::array_t<T>(shape, p, owner);
}

// Scratch memory straight from mmap, so that freeing it hands it back to the system
// at once (from malloc it may stay in the heap, and count in the peak, when glibc's
// adaptive mmap threshold has grown past its size).
template <class T>
class MappedArray {
 public:
  explicit MappedArray(std::size_t n) : bytes_(std::max<std::size_t>(1, n * sizeof(T))) {
    void* p = mmap(nullptr, bytes_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    data_ = static_cast<T*>(p);
  }
  ~MappedArray() { munmap(data_, bytes_); }
  MappedArray(const MappedArray&) = delete;
  MappedArray& operator=(const MappedArray&) = delete;
  T* get() { return data_; }

 private:
  std::size_t bytes_;
  T* data_ = nullptr;
};

// Capacity for n values, on huge pages when large (see Buffer), before the first touch.
template <class T>
void reserve_huge(std::vector<T>& v, std::size_t n) {
  v.reserve(n);
  if (n * sizeof(T) >= (std::size_t(4) << 20)) core::advise_huge_pages(v.data(), n * sizeof(T));
}

template <class T>
py::array_t<T> vector_to_array(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(v));
  py::capsule owner(owned, [](void* q) { delete static_cast<std::vector<T>*>(q); });
  return py::array_t<T>(shape, owned->empty() ? nullptr : owned->data(), owner);
}

// ---- logging: the pipeline logs through spdlog; the lines wait in a queue for the ----
// calling thread, which hands them to Python (a job's worker threads never take the GIL).

class QueueSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  std::vector<std::pair<int, std::string>> take() {
    std::lock_guard<std::mutex> lock(this->mutex_);
    return std::exchange(lines_, {});
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    lines_.emplace_back(int(msg.level), std::string(msg.payload.data(), msg.payload.size()));
  }
  void flush_() override {}

 private:
  std::vector<std::pair<int, std::string>> lines_;
};

QueueSink& log_queue() {
  static const std::shared_ptr<QueueSink> sink = [] {
    auto q = std::make_shared<QueueSink>();
    auto logger = std::make_shared<spdlog::logger>("tetstream", q);
    spdlog::set_default_logger(logger);
    return q;
  }();
  return *sink;
}

void configure_logging(bool verbose) {
  log_queue();
  spdlog::set_level(verbose ? spdlog::level::info : spdlog::level::warn);
}

// Hands the queued lines to `emit(level, message)` (spdlog's level numbers). Needs the GIL.
void drain_log(const py::object& emit) {
  for (auto& [level, line] : log_queue().take())
    if (!emit.is_none()) emit(level, line);
}

// Waits for `done` with the GIL released, waking ten times a second to hand the queued
// log lines to `emit` and to let Python run its signal handlers. On a signal (Ctrl-C:
// KeyboardInterrupt from Python's handler) it calls `stop`, waits for the work to
// unwind, and returns the Python error, fetched (and cleared), for the caller to raise.
template <class R>
std::optional<py::error_already_set> wait_for_work(std::future<R>& done, const std::function<void()>& stop,
                                                   const py::object& emit) {
  std::optional<py::error_already_set> pending;
  for (;;) {
    bool ready;
    {
      py::gil_scoped_release release;
      ready = done.wait_for(std::chrono::milliseconds(100)) == std::future_status::ready;
    }
    drain_log(emit);
    if (ready) break;
    if (PyErr_CheckSignals() != 0) {
      pending.emplace();
      stop();
      {
        py::gil_scoped_release release;
        done.wait();
      }
      break;
    }
  }
  drain_log(emit);
  return pending;
}

// ---- in core: the kernel ----

// Whether the kernel's 32-bit ids hold n points (caller ids below 2^31, tet ids below
// 2^30 at the kernel's estimate of 6.9 tets per point, with some headroom).
constexpr std::size_t kMaxInCorePoints = std::size_t(150'000'000);

// The kernel's answer in the caller's terms. The kernel numbers points by their
// position in its input, a permutation of the caller's array: input[k] is the caller's
// index of the kernel's point k. Of several exact copies of a point, the first in the
// caller's order stands for all of them (the vertex), as `run` keeps the first.
template <class I>
py::dict triangulation_arrays(const core::Delaunay& dt, const std::vector<std::uint32_t>& input, int threads) {
  const std::size_t n = input.size();
  // Output index of each finite tet slot: counted per block, then numbered, in parallel.
  const std::size_t slots = dt.num_tet_slots();
  constexpr std::uint32_t kNone = 0xFFFFFFFFu;
  Buffer<I> simplices, neighbors, hull, duplicates;
  std::size_t m = 0, h = 0, d = 0;
  {
    py::gil_scoped_release release;
    // name[k]: the caller's index that kernel point k's vertex goes by (the smallest of
    // its copies); rows of `duplicates` for every other copy.
    std::vector<std::uint32_t> name(n);
    for (std::size_t k = 0; k < n; ++k) name[k] = input[k];
    std::vector<std::pair<std::uint32_t, std::uint32_t>> merged;  // (kernel point, its vertex)
    for (std::size_t k = 0; k < n; ++k)
      if (dt.incident_tet(core::VertexId(k)) == core::kNoTet) {
        core::VertexId to = dt.duplicate_of(core::VertexId(k));
        // (the first point with these coordinates; follow it to the vertex if need be)
        for (int guard = 0; guard < 64 && dt.incident_tet(to) == core::kNoTet && dt.duplicate_of(to) != to; ++guard)
          to = dt.duplicate_of(to);
        merged.emplace_back(std::uint32_t(k), std::uint32_t(to));
        name[to] = std::min(name[to], input[k]);
      }
    d = merged.size();
    const auto finite = [&dt](std::size_t t) { return dt.is_alive(core::TetId(t)) && !dt.is_infinite(core::TetId(t)); };
    constexpr std::size_t kBlock = std::size_t(1) << 16;
    const std::size_t blocks = (slots + kBlock - 1) / kBlock;
    std::vector<std::size_t> first(blocks + 1, 0);
#pragma omp parallel for schedule(static) num_threads(threads)
    for (std::size_t b = 0; b < blocks; ++b) {
      std::size_t c = 0;
      for (std::size_t t = b * kBlock, e = std::min(slots, t + kBlock); t < e; ++t) c += finite(t);
      first[b + 1] = c;
    }
    for (std::size_t b = 0; b < blocks; ++b) first[b + 1] += first[b];
    m = first[blocks];
    // Neighbours first, through the slot -> index map, which is freed before the
    // simplices are allocated: the peak holds the kernel and two of the three.
    neighbors = Buffer<I>(4 * m);
    I* nb = neighbors.get();
    {
      MappedArray<std::uint32_t> index(slots);
      std::uint32_t* ix = index.get();
#pragma omp parallel for schedule(static) num_threads(threads)
      for (std::size_t b = 0; b < blocks; ++b) {
        std::uint32_t next = std::uint32_t(first[b]);
        for (std::size_t t = b * kBlock, e = std::min(slots, t + kBlock); t < e; ++t)
          ix[t] = finite(t) ? next++ : kNone;
      }
#pragma omp parallel for schedule(static) num_threads(threads) reduction(+ : h)
      for (std::size_t t = 0; t < slots; ++t) {
        const std::uint32_t i = ix[t];
        if (i == kNone) continue;
        for (int j = 0; j < 4; ++j) {
          const std::uint32_t other = ix[dt.neighbor(core::TetId(t), j) >> 2];
          if (other == kNone) ++h;  // across facet j: an infinite tet, the hull
          nb[4 * std::size_t(i) + j] = other == kNone ? I(-1) : I(other);
        }
      }
    }
    simplices = Buffer<I>(4 * m);
    I* s = simplices.get();
#pragma omp parallel for schedule(static) num_threads(threads)
    for (std::size_t b = 0; b < blocks; ++b) {
      std::size_t i = first[b];
      for (std::size_t t = b * kBlock, e = std::min(slots, t + kBlock); t < e; ++t) {
        if (!finite(t)) continue;
        for (int j = 0; j < 4; ++j) s[4 * i + j] = I(name[dt.vertex(core::TetId(t), j)]);
        ++i;
      }
    }
    // Hull facets, oriented outwards (counter-clockwise seen from outside). The
    // kernel's facet order kFacetVertex[j] sees the tet's own vertex j, inside the
    // hull, on its positive side; two vertices swapped turn the normal outwards.
    hull = Buffer<I>(3 * h);
    I* f = hull.get();
    std::size_t k = 0;
    for (std::size_t i = 0; i < m; ++i)
      for (int j = 0; j < 4; ++j)
        if (nb[4 * i + j] == I(-1)) {
          const I* v = s + 4 * i;
          f[3 * k + 0] = v[core::kFacetVertex[j][0]];
          f[3 * k + 1] = v[core::kFacetVertex[j][2]];
          f[3 * k + 2] = v[core::kFacetVertex[j][1]];
          ++k;
        }
    // Duplicates: every copy but the first of each point, and the first, sorted by the
    // copy's index. (The kernel kept whichever copy it inserted first: the vertex's
    // own point is a duplicate row when an earlier copy names the vertex.)
    std::vector<std::pair<std::uint32_t, std::uint32_t>> rows;
    rows.reserve(d);
    for (const auto& [copy, vertex] : merged) {
      const std::uint32_t keep = name[vertex];
      if (input[copy] != keep) rows.emplace_back(input[copy], keep);
      if (input[vertex] != keep) rows.emplace_back(input[vertex], keep);
    }
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    d = rows.size();
    duplicates = Buffer<I>(2 * d);
    I* dp = duplicates.get();
    for (std::size_t r = 0; r < d; ++r) dp[2 * r] = I(rows[r].first), dp[2 * r + 1] = I(rows[r].second);
  }
  py::dict out;
  out["simplices"] = to_array(std::move(simplices), {py::ssize_t(m), 4});
  out["neighbors"] = to_array(std::move(neighbors), {py::ssize_t(m), 4});
  out["convex_hull"] = to_array(std::move(hull), {py::ssize_t(h), 3});
  out["duplicates"] = to_array(std::move(duplicates), {py::ssize_t(d), 2});
  return out;
}

// The kernel's build, in pieces so that it can stop between them: the points in the
// kernel's biased randomized order (core::brio_order, what build() uses), copied in
// that order with their caller indices as labels (the symbolic perturbation stays
// keyed by the input index); build() on the first piece, then insert_range() on the
// next ones, which takes each piece in Hilbert order, as build() sorts a round. Sets
// `input` (kernel point -> caller index). Returns false when `stop` was raised.
bool build_in_pieces(core::Delaunay& dt, const double* xyz, std::size_t n, std::vector<std::uint32_t>& input,
                     const std::atomic<bool>& stop, core::BuildStatus& status) {
  input = core::brio_order(xyz, n);
  std::vector<double> sorted(3 * n);
  std::vector<std::uint64_t> labels(n);
  for (std::size_t k = 0; k < n; ++k) {
    const double* p = xyz + 3 * std::size_t(input[k]);
    sorted[3 * k] = p[0], sorted[3 * k + 1] = p[1], sorted[3 * k + 2] = p[2];
    labels[k] = input[k];
  }
  constexpr std::size_t kPiece = std::size_t(1) << 16;
  std::size_t done = std::min(n, kPiece);
  status = dt.build(sorted.data(), labels.data(), done);
  if (status != core::BuildStatus::kOk && done < n) {
    // Too few independent points in the first piece (a nearly flat input): all at once.
    done = n;
    status = dt.build(sorted.data(), labels.data(), n);
  }
  if (status != core::BuildStatus::kOk) return true;
  dt.reserve(n);
  dt.set_points(sorted.data(), labels.data(), n);
  while (done < n) {
    if (stop.load(std::memory_order_relaxed)) return false;
    const std::size_t next = std::min(n, done + kPiece);
    dt.insert_range(core::VertexId(done), core::VertexId(next));
    done = next;
  }
  // The kernel keeps its own copy of the coordinates; its point() and label() are not
  // asked again, so the sorted copies go with this function.
  return true;
}

// points: a C-contiguous (N, 3) float64 array (the Python side converts others).
py::dict delaunay(py::array_t<double, py::array::c_style> points, const std::string& index_dtype, int threads) {
  if (points.ndim() != 2 || points.shape(1) != 3) throw UsageError("points must be an (N, 3) array");
  const std::size_t n = std::size_t(points.shape(0));
  if (n > kMaxInCorePoints)
    throw UsageError(std::to_string(n) + " points are more than the in-memory kernel holds (" +
                     std::to_string(kMaxInCorePoints) + "); use tetstream.run(), which works out of core");
  if (index_dtype == "int32" && n > std::size_t(0x7FFFFFFF)) throw UsageError("int32 indices cannot hold N points");
  const double* xyz = points.data();
  {
    py::gil_scoped_release release;
    for (std::size_t i = 0; i < 3 * n; ++i)
      if (!std::isfinite(xyz[i]))
        throw InputError("points: row " + std::to_string(i / 3) + ": a coordinate is not finite");
  }
  auto dt = std::make_unique<core::Delaunay>();
  std::vector<std::uint32_t> input;
  core::BuildStatus status = core::BuildStatus::kOk;
  std::atomic<bool> stop{false};
  // On a thread of its own, so that this one can run Python's signal handlers (Ctrl-C
  // raises KeyboardInterrupt once the build has stopped at the end of a piece).
  std::packaged_task<bool()> task([&] { return build_in_pieces(*dt, xyz, n, input, stop, status); });
  std::future<bool> done = task.get_future();
  std::thread worker(std::move(task));
  std::optional<py::error_already_set> pending;
  try {
    pending = wait_for_work(
        done, [&stop] { stop.store(true); }, py::none());
  } catch (...) {
    stop.store(true);
    py::gil_scoped_release release;
    worker.join();
    throw;
  }
  {
    py::gil_scoped_release release;
    worker.join();
  }
  const bool finished = done.get();  // rethrows the build's own failure (std::bad_alloc)
  if (pending) {
    py::gil_scoped_release release;
    dt.reset();
  }
  if (pending) throw *pending;
  if (!finished) throw std::logic_error("the triangulation stopped without a signal");
  if (status != core::BuildStatus::kOk)
    throw InputError("points: fewer than 4 affinely independent distinct points (" + std::to_string(n) +
                     " given): no tetrahedron");
  const int team = threads > 0 ? threads : omp_get_max_threads();
  py::dict out = index_dtype == "int32" ? triangulation_arrays<std::int32_t>(*dt, input, team)
                                        : triangulation_arrays<std::int64_t>(*dt, input, team);
  {
    py::gil_scoped_release release;
    dt.reset();  // the kernel's arrays go before Python sees the result
  }
  return out;
}

// ---- out of core: the job ----

std::string get_string(const py::handle& v) { return py::str(v).cast<std::string>(); }

// Fills `o` from the keyword options of tetstream.run (names as the CLI's options, with
// '_' for '-'). Unknown names: TypeError, as Python does for unknown keywords.
void apply_run_options(pipeline::RunOptions& o, const py::dict& options) {
  for (const auto& [key, value] : options) {
    const std::string k = key.cast<std::string>();
    if (value.is_none()) continue;
    if (k == "tmpdir")
      o.tmpdir = get_string(value);
    else if (k == "buffer")
      o.buffer_spacings = value.cast<double>();
    else if (k == "segment_points" || k == "zone_points")
      o.segment_points = value.cast<std::uint64_t>();
    else if (k == "zones") {
      const int z = value.cast<int>();
      if (z < 0 || z > 4096) throw UsageError("zones must be in [0, 4096]");
      o.zones = z;
    } else if (k == "sort_run_points")
      o.sort_run_points = value.cast<std::uint64_t>();
    else if (k == "checkpoint") {
      // True/False, or the directory in which to make the checkpoint.
      if (py::isinstance<py::bool_>(value))
        o.checkpoint = value.cast<bool>();
      else
        o.checkpoint = true, o.checkpoint_dir = get_string(value);
    } else if (k == "force")
      o.force = value.cast<bool>();
    else if (k == "labels") {
      const std::string l = get_string(value);
      if (l != "bricks" && l != "sorted") throw UsageError("labels: expected bricks or sorted, got '" + l + "'");
      o.brick_labels = l == "bricks";
    } else if (k == "format")
      io::parse_format_name(get_string(value), o.read.format, o.read.type);
    else if (k == "type") {
      const std::string t = get_string(value);
      if (t == "f32" || t == "float32")
        o.read.type = io::ScalarType::kFloat32;
      else if (t == "f64" || t == "float64")
        o.read.type = io::ScalarType::kFloat64;
      else
        throw UsageError("type: expected f32 or f64, got '" + t + "'");
    } else if (k == "stride")
      o.read.stride = value.cast<std::uint64_t>();
    else if (k == "offset")
      o.read.offset = value.cast<std::uint64_t>();
    else if (k == "byte_order")
      o.read.byte_order = io::parse_byte_order(get_string(value));
    else if (k == "columns")
      o.read.columns = value.cast<std::vector<std::uint64_t>>();
    else if (k == "properties")
      o.read.properties = value.cast<std::vector<std::string>>();
    else if (k == "datasets" || k == "dataset") {
      if (py::isinstance<py::str>(value))
        o.read.datasets = {get_string(value)};
      else
        o.read.datasets = value.cast<std::vector<std::string>>();
    } else {
      throw py::type_error("run() got an unexpected keyword argument '" + k + "'");
    }
  }
}

// Runs `work` on a thread of its own (wait_for_work above): Ctrl-C asks the job to
// stop (pipeline::request_interrupt), the job unwinds through its cleanup (a
// checkpointed run keeps its checkpoint), and the Python exception is raised here once
// it has.
// One job (run, verify or field) at a time per process: they share the interrupt flag
// and the log level.
std::mutex g_job_mutex;

template <class R>
R run_interruptible(std::function<R()> work, const py::object& emit) {
  std::unique_lock<std::mutex> one_job(g_job_mutex, std::try_to_lock);
  if (!one_job.owns_lock())
    throw UsageError("another tetstream.run(), verify() or field() is running in this process: one at a time");
  pipeline::clear_interrupt();
  std::packaged_task<R()> task(std::move(work));
  std::future<R> done = task.get_future();
  std::thread worker(std::move(task));
  std::optional<py::error_already_set> pending;
  try {
    pending = wait_for_work(
        done, [] { pipeline::request_interrupt(SIGINT); }, emit);
  } catch (...) {  // an exception from `emit`: the job still has to stop before we leave
    pipeline::request_interrupt(SIGINT);
    py::gil_scoped_release release;
    worker.join();
    pipeline::clear_interrupt();
    throw;
  }
  {
    py::gil_scoped_release release;
    worker.join();
  }
  pipeline::clear_interrupt();
  if (pending) {
    // The job stopped because of it (its own Interrupted is not news); a job that
    // failed otherwise meanwhile is reported through its own error.
    try {
      done.get();
    } catch (const pipeline::Interrupted&) {
    } catch (...) {
      throw;
    }
    throw *pending;
  }
  return done.get();
}

std::string run(const std::string& input, const std::vector<std::string>& more_inputs, const std::string& output,
                std::uint64_t memory_bytes, int threads, bool progress, bool resume, const py::dict& options,
                const py::object& emit) {
  pipeline::RunOptions o;
  o.input = input;
  o.read.more_inputs = more_inputs;
  o.output = output;
  o.memory_bytes = memory_bytes;
  if (threads < 0 || threads > 1024) throw UsageError("threads must be in [1, 1024] (or None: all cores)");
  o.threads = threads;
  o.progress = progress;
  o.resume = resume;
  // periodic=L, (Lx, Ly, Lz) or "auto": the flat torus (docs/periodic.md).
  py::dict rest;
  std::optional<pipeline::periodic::PeriodicOptions> periodic;
  for (const auto& [key, value] : options) {
    const std::string k = key.cast<std::string>();
    if (k == "periodic" && !value.is_none()) {
      periodic.emplace();
      if (py::isinstance<py::str>(value))
        periodic->period = pipeline::periodic::parse_period(get_string(value), input);
      else if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value))
        periodic->period.fill(value.cast<double>());
      else
        periodic->period = value.cast<std::array<double, 3>>();
    } else if (k == "periodic_outside") {
      const std::string v = get_string(value);
      if (v != "wrap" && v != "refuse") throw UsageError("periodic_outside must be 'wrap' or 'refuse'");
      if (!periodic) periodic.emplace();
      periodic->wrap = v == "wrap";
    } else {
      rest[key] = value;
    }
  }
  apply_run_options(o, rest);
  if (periodic && periodic->period[0] == 0) throw UsageError("periodic_outside needs periodic=L");
  if (periodic) {
    io::forget_noted_files();
    return run_interruptible<std::string>(
        [o, p = *periodic] {
          configure_logging(o.progress);
          if (o.threads > 0) omp_set_num_threads(o.threads);
          return pipeline::periodic::periodic_summary_json(o, p, pipeline::periodic::run_periodic(o, p)).dump();
        },
        emit);
  }
  if (o.resume && o.force) throw UsageError("resume and force exclude each other");
  if (io::is_std_stream(o.input) || io::is_std_stream(o.output))
    throw UsageError("standard input/output ('-') is for the command line; give file names");
  io::forget_noted_files();  // this job's inputs are noted as it opens them
  return run_interruptible<std::string>(
      [o] {
        configure_logging(o.progress);
        if (o.threads > 0) omp_set_num_threads(o.threads);
        const pipeline::RunSummary s = pipeline::run_job(o);
        return pipeline::run_summary_json(o, s).dump();
      },
      emit);
}

// A periodic container's tets (docs/periodic.md): (M, 4) input indices, (M, 4, 3)
// offsets in periods (int8), the period, and the points in the input's order.
py::dict periodic_tets(const std::string& path) {
  const io::TetReader r(path, io::TetReader::Periodic::kAccept);
  if (!r.periodic()) throw InputError(path + ": not a periodic container");
  r.verify_points();
  const io::PeriodicBox box = io::parse_periodic_box(r.section(io::kTagPeriodicBox), path);
  const io::PeriodicOffsetsReader offsets(r);
  const std::size_t n = r.point_count(), m = r.tet_count();
  std::vector<double> xyz(3 * n);
  std::vector<std::uint64_t> ids(n);
  r.read_points(0, n, xyz.data(), ids.data());
  py::array_t<std::int64_t> simplices({m, std::size_t(4)});
  py::array_t<std::int8_t> off({m, std::size_t(4), std::size_t(3)});
  auto s = simplices.mutable_unchecked<2>();
  auto o = off.mutable_unchecked<3>();
  std::size_t t = 0;
  pipeline::periodic::for_each_stored_tet(r, offsets,
                                          [&](const pipeline::periodic::KeptTet& k, std::uint64_t, std::size_t) {
                                            int v[4][3];
                                            pipeline::periodic::stored_offsets(k, v);
                                            for (py::ssize_t j = 0; j < 4; ++j) {
                                              s(py::ssize_t(t), j) = std::int64_t(ids[k.v[j]]);
                                              for (py::ssize_t c = 0; c < 3; ++c)
                                                o(py::ssize_t(t), j, c) = std::int8_t(v[j][c]);
                                            }
                                            ++t;
                                          });
  py::dict d;
  d["simplices"] = simplices;
  d["offsets"] = off;
  d["period"] = box.period;
  return d;
}

// An array written to PATH for run(array): through io::OutputFile, the one way
// tetstream opens an output (PATH.partial claimed without following a link and
// locked, renamed when complete, removed on failure), with the GIL released.
void spill_array(const std::string& path, const py::array& array) {
  if (!(array.flags() & py::array::c_style)) throw UsageError("spill: the array must be C-contiguous");
  const char* data = static_cast<const char*>(array.data());
  const std::size_t bytes = std::size_t(array.nbytes());
  io::forget_noted_files();
  py::gil_scoped_release release;
  // A PATH.partial that was there before is not this call's to reuse (another
  // process's spill, or a file of the user's): refused, and left as it is.
  const io::OutputClaim claim(path);
  if (!claim.created())
    throw UsageError(path +
                     ".partial exists: another job is writing this input, or one was killed (remove it if "
                     "no job runs)");
  io::OutputFile f(path, std::size_t(8) << 20, &claim);
  f.write(data, bytes);
  f.commit();
}

std::uint64_t memory_size(const py::object& memory) {
  if (py::isinstance<py::int_>(memory)) {
    const long long b = memory.cast<long long>();
    if (b <= 0) throw UsageError("memory must be positive");
    return std::uint64_t(b);
  }
  return pipeline::parse_memory_size(get_string(memory));
}

// ---- verify ----

std::string verify(const std::string& path, const py::object& memory, double sample, std::uint64_t seed,
                   const std::string& tmpdir, double volume_tolerance, std::size_t max_listed, bool progress,
                   int threads, const py::object& emit) {
  if (threads < 0 || threads > 1024) throw UsageError("threads must be in [1, 1024] (or None: all cores)");
  pipeline::VerifyOptions o;
  o.memory_bytes = memory_size(memory);
  o.sample = sample;
  o.seed = seed;
  o.tmpdir = tmpdir;
  o.volume_tolerance = volume_tolerance;
  o.max_listed = max_listed;
  o.progress = progress;
  o.validate();
  return run_interruptible<std::string>(
      [o, path, threads] {
        configure_logging(o.progress);
        if (threads > 0) omp_set_num_threads(threads);
        return pipeline::verify_report_json(pipeline::verify_file(path, o), path).dump();
      },
      emit);
}

// ---- fields: pipeline::compute_fields over a container, or its sums in memory ----

py::dict field(const std::string& input, const std::string& prefix, bool density, bool voronoi, bool neighbours,
               std::array<std::uint64_t, 3> grid, const std::optional<std::array<double, 6>>& box,
               const std::string& hull, const std::string& dtype, bool neighbour_int64, const std::string& mass,
               const py::object& memory, const std::string& tmpdir, bool progress, int threads,
               const py::object& emit) {
  if (threads < 0 || threads > 1024) throw UsageError("threads must be in [1, 1024] (or None: all cores)");
  pipeline::FieldOptions o;
  o.input = input;
  o.output = prefix;
  o.density = density;
  o.voronoi = voronoi;
  o.neighbours = neighbours;
  o.grid = grid;
  if (box) o.box = *box, o.has_box = true;
  if (hull != "nan" && hull != "open") throw UsageError("hull must be 'nan' or 'open', not '" + hull + "'");
  o.hull = hull == "open" ? pipeline::HullMode::kOpen : pipeline::HullMode::kNan;
  if (dtype != "float64" && dtype != "float32")
    throw UsageError("dtype must be float64 or float32, not '" + dtype + "'");
  o.dtype = dtype == "float32" ? pipeline::FieldType::kFloat32 : pipeline::FieldType::kFloat64;
  o.neighbour_int64 = neighbour_int64;
  o.mass = mass;
  o.memory_bytes = memory_size(memory);
  o.tmpdir = tmpdir;
  o.progress = progress;
  o.validate();
  const pipeline::FieldSummary sm = run_interruptible<pipeline::FieldSummary>(
      [o, threads] {
        configure_logging(o.progress);
        if (threads > 0) omp_set_num_threads(threads);
        return pipeline::compute_fields(o);
      },
      emit);
  py::dict files;
  for (const auto& f : sm.files) files[py::str(f.what)] = f.path;
  py::dict d;
  d["files"] = files;
  d["points"] = sm.points;
  d["hull_points"] = sm.hull_points;
  d["tets"] = sm.tets;
  d["total_mass"] = sm.total_mass;
  d["hull_volume"] = sm.tet_volume;
  d["interior_voronoi_volume"] = sm.interior_voronoi;
  d["voronoi_total_with_hull_pieces"] = sm.voronoi_total;
  d["neighbour_entries"] = sm.neighbour_entries;
  d["grid_points"] = sm.grid_points;
  d["grid_inside"] = sm.grid_inside;
  d["seconds"] = sm.seconds;
  return d;
}

// The per-point sums of `tetstream field` over an in-memory triangulation, with the
// same per-tet geometry (pipeline::tet_contribution): the volume of each point's star
// and, with `voronoi`, its Voronoi cell's pieces; and whether it is on the hull (a
// vertex of a facet without a neighbour). Points that are no vertex get star volume 0.
template <class I>
py::tuple field_sums_t(const double* xyz, std::size_t npoints, const py::array& simplices, const py::array& neighbors,
                       bool voronoi, int threads) {
  const std::size_t m = std::size_t(simplices.shape(0));
  const I* s = static_cast<const I*>(simplices.data());
  const I* nb = static_cast<const I*>(neighbors.data());
  py::array_t<double> star{py::ssize_t(npoints)}, cell{py::ssize_t(voronoi ? npoints : 0)};
  py::array_t<bool> on_hull{py::ssize_t(npoints)};
  double* st = star.mutable_data();
  double* ce = cell.mutable_data();
  bool* hu = on_hull.mutable_data();
  {
    py::gil_scoped_release release;
    for (std::size_t i = 0; i < 4 * m; ++i)
      if (s[i] < 0 || std::size_t(s[i]) >= npoints) throw UsageError("simplices: an index out of range");
    std::fill(st, st + npoints, 0.0);
    if (voronoi) std::fill(ce, ce + npoints, 0.0);
    std::fill(hu, hu + npoints, false);
    // Contributions in parallel a block at a time, summed in tet order by one thread
    // (the same sums whatever the thread count).
    constexpr std::size_t kBlock = std::size_t(1) << 16;
    std::vector<pipeline::TetContribution> part(std::min(m, kBlock));
    for (std::size_t b = 0; b < m; b += kBlock) {
      const std::size_t e = std::min(m, b + kBlock);
#pragma omp parallel for schedule(static) num_threads(threads)
      for (std::size_t t = b; t < e; ++t) {
        const double* p[4];
        for (int j = 0; j < 4; ++j) p[j] = xyz + 3 * std::size_t(s[4 * t + j]);
        part[t - b] = pipeline::tet_contribution(p, voronoi);
      }
      for (std::size_t t = b; t < e; ++t) {
        const pipeline::TetContribution& c = part[t - b];
        for (int j = 0; j < 4; ++j) {
          const std::size_t v = std::size_t(s[4 * t + j]);
          st[v] += c.volume;
          if (voronoi) ce[v] += c.voronoi[j];
          if (nb[4 * t + j] < 0)
            for (int k = 0; k < 4; ++k)
              if (k != j) hu[std::size_t(s[4 * t + k])] = true;
        }
      }
    }
  }
  return py::make_tuple(star, cell, on_hull);
}

py::tuple field_sums(py::array_t<double, py::array::c_style> points, py::array simplices, py::array neighbors,
                     bool voronoi, int threads) {
  if (points.ndim() != 2 || points.shape(1) != 3) throw UsageError("points: expected an (N, 3) array");
  for (const py::array* a : {&simplices, &neighbors})
    if (a->ndim() != 2 || a->shape(1) != 4 || !(a->flags() & py::array::c_style))
      throw UsageError("simplices and neighbors: expected C-contiguous (M, 4) arrays");
  if (simplices.shape(0) != neighbors.shape(0)) throw UsageError("simplices and neighbors differ in length");
  const int team = threads > 0 ? threads : omp_get_max_threads();
  const std::size_t n = std::size_t(points.shape(0));
  if (simplices.dtype().is(py::dtype::of<std::int64_t>()) && neighbors.dtype().is(py::dtype::of<std::int64_t>()))
    return field_sums_t<std::int64_t>(points.data(), n, simplices, neighbors, voronoi, team);
  if (simplices.dtype().is(py::dtype::of<std::int32_t>()) && neighbors.dtype().is(py::dtype::of<std::int32_t>()))
    return field_sums_t<std::int32_t>(points.data(), n, simplices, neighbors, voronoi, team);
  throw UsageError("simplices and neighbors must both be int32 or int64");
}

// ---- files: a container to a mesh (`tetstream convert`), the CLI's globs, a point file ----

std::vector<std::string> convert(const std::string& input, const std::string& output, bool binary, int compress) {
  py::gil_scoped_release release;
  const io::TetReader reader(input);
  io::MeshExportOptions options;
  options.binary = binary;
  options.compress_level = compress;
  return io::export_mesh(reader, output, io::mesh_format_for(output), options).files;
}

py::array_t<double> read_points(const std::string& path) {
  std::vector<double> xyz;
  {
    py::gil_scoped_release release;
    auto reader = io::open_points(path, io::PointReadOptions{});
    constexpr std::size_t kChunk = std::size_t(1) << 16;
    std::vector<double> chunk(3 * kChunk);
    while (const std::size_t k = reader->read(chunk.data(), kChunk))
      xyz.insert(xyz.end(), chunk.begin(), chunk.begin() + 3 * k);
  }
  const py::ssize_t n = py::ssize_t(xyz.size() / 3);
  return vector_to_array(std::move(xyz), {n, 3});
}

// ---- reading a container ----

class Reader {
 public:
  explicit Reader(const std::string& path) {
    py::gil_scoped_release release;
    reader_ = std::make_unique<io::TetReader>(path, io::TetReader::Periodic::kAccept);
    if (reader_->periodic()) {
      box_ = io::parse_periodic_box(reader_->section(io::kTagPeriodicBox), path);
      offsets_ = std::make_unique<io::PeriodicOffsetsReader>(*reader_);
    }
  }

  const io::TetReader& r() const {
    if (!reader_) throw UsageError("the container is closed");
    return *reader_;
  }
  // The points section's CRC, checked once before any coordinate or original id is
  // handed out (as `cat --points` and `--original-ids` do): a damaged section would
  // otherwise give wrong numbers silently. Called without the GIL.
  const io::TetReader& checked_points() const {
    const io::TetReader& rd = r();
    std::call_once(points_checked_, [&rd] { rd.verify_points(); });
    return rd;
  }
  void close() {
    py::gil_scoped_release release;
    offsets_.reset();
    reader_.reset();
  }
  bool closed() const { return !reader_; }

  py::dict header() const {
    const io::TetFileHeader& h = r().header();
    py::dict d;
    d["path"] = r().path();
    d["points"] = h.point_count;
    d["input_points"] = h.input_count;
    d["tets"] = r().tet_count();
    d["frames"] = r().frame_count();
    d["coord_type"] = h.coord_type == io::CoordType::kFloat32 ? "float32" : "float64";
    d["label_width"] = h.label_width;
    d["id_width"] = h.id_width;
    d["bbox_min"] = py::make_tuple(h.bbox_min[0], h.bbox_min[1], h.bbox_min[2]);
    d["bbox_max"] = py::make_tuple(h.bbox_max[0], h.bbox_max[1], h.bbox_max[2]);
    d["tool"] = h.tool;
    d["options"] = h.options;
    d["version"] = py::make_tuple(r().version_major(), r().version_minor());
    d["file_bytes"] = r().file_bytes();
    d["tet_bytes"] = r().tet_bytes();
    d["periodic"] = offsets_ ? py::object(py::make_tuple(box_.period[0], box_.period[1], box_.period[2])) : py::none();
    return d;
  }

  // A periodic container's frame k: each tet's vertex offsets in periods relative to
  // its first vertex (docs/periodic.md), a (t, 4, 3) int8 array (row 0 is zero).
  py::array frame_offsets(std::uint64_t k) const {
    const io::TetReader& rd = r();
    if (!offsets_) throw UsageError(rd.path() + ": not a periodic container (it has no offsets)");
    if (k >= rd.frame_count()) throw py::index_error("frame " + std::to_string(k) + " out of range");
    std::vector<std::uint16_t> codes;
    {
      py::gil_scoped_release release;
      offsets_->read(k, codes);
    }
    py::array_t<std::int8_t> out({codes.size(), std::size_t(4), std::size_t(3)});
    auto o = out.mutable_unchecked<3>();
    for (std::size_t t = 0; t < codes.size(); ++t) {
      int vertex[3];
      io::tet_offset_codes(codes[t], vertex);
      for (py::ssize_t c = 0; c < 3; ++c) o(py::ssize_t(t), 0, c) = 0;
      for (int v = 0; v < 3; ++v) {
        int off[3];
        io::offset_of_code(vertex[v], off);
        for (int c = 0; c < 3; ++c) o(py::ssize_t(t), v + 1, c) = std::int8_t(off[c]);
      }
    }
    return out;
  }

  // Points [first, first + n) by label: coordinates (n, 3) float64 and original ids.
  py::tuple points(std::uint64_t first, std::uint64_t count, bool xyz, bool ids) const {
    const io::TetReader& rd = r();
    if (first > rd.point_count()) first = rd.point_count();
    const std::uint64_t n = std::min(count, rd.point_count() - first);
    Buffer<double> c(xyz ? 3 * n : 0);
    Buffer<std::int64_t> i(ids ? n : 0);
    {
      py::gil_scoped_release release;
      checked_points();
      rd.read_points(first, std::size_t(n), xyz ? c.get() : nullptr,
                     ids ? reinterpret_cast<std::uint64_t*>(i.get()) : nullptr);
    }
    py::object a = xyz ? py::object(to_array(std::move(c), {py::ssize_t(n), 3})) : py::none();
    py::object b = ids ? py::object(to_array(std::move(i), {py::ssize_t(n)})) : py::none();
    return py::make_tuple(a, b);
  }

  // Frame k as a (t, 4) array of labels (or original ids): int64, or uint32 when
  // `narrow` (the container's 32-bit labels decoded without widening).
  py::array frame(std::uint64_t k, bool original_ids, bool narrow, bool release_pages) const {
    const io::TetReader& rd = r();
    if (k >= rd.frame_count()) throw py::index_error("frame " + std::to_string(k) + " out of range");
    const std::size_t values = 4 * std::size_t(rd.frames()[k].tet_count);
    if (narrow && !original_ids) {
      std::vector<std::uint32_t> labels;
      reserve_huge(labels, values);
      {
        py::gil_scoped_release release;
        rd.read_frame(k, labels);
        if (release_pages) rd.release_frame_pages(k);
      }
      const py::ssize_t t = py::ssize_t(labels.size() / 4);
      return vector_to_array(std::move(labels), {t, 4});
    }
    std::vector<std::uint64_t> labels;
    reserve_huge(labels, values);
    {
      py::gil_scoped_release release;
      rd.read_frame(k, labels);
      if (release_pages) rd.release_frame_pages(k);
      if (original_ids) checked_points().map_to_original(labels);
    }
    const py::ssize_t t = py::ssize_t(labels.size() / 4);
    if (narrow) {
      std::vector<std::uint32_t> out(labels.size());
      for (std::size_t i = 0; i < labels.size(); ++i) {
        if (labels[i] > 0xFFFFFFFFull) throw UsageError("an index does not fit uint32; read int64");
        out[i] = std::uint32_t(labels[i]);
      }
      return vector_to_array(std::move(out), {t, 4});
    }
    // Labels and ids are below 2^63: the same bytes read as int64.
    static_assert(sizeof(std::int64_t) == sizeof(std::uint64_t));
    auto* owned = new std::vector<std::uint64_t>(std::move(labels));
    py::capsule owner(owned, [](void* q) { delete static_cast<std::vector<std::uint64_t>*>(q); });
    return py::array_t<std::int64_t>({t, py::ssize_t(4)}, reinterpret_cast<std::int64_t*>(owned->data()), owner);
  }

  // Tets with ordinals [start, stop) in stored order, through the frame index: only
  // the frames that hold them are decoded.
  py::array tets(std::uint64_t start, std::uint64_t stop, bool original_ids) const {
    const io::TetReader& rd = r();
    stop = std::min(stop, rd.tet_count());
    start = std::min(start, stop);
    const std::uint64_t n = stop - start;
    Buffer<std::int64_t> out(4 * n);
    {
      py::gil_scoped_release release;
      const auto& frames = rd.frames();
      // The first frame whose tets reach past `start`.
      auto it = std::upper_bound(frames.begin(), frames.end(), start, [](std::uint64_t s, const io::FrameEntry& f) {
        return s < f.first_tet + f.tet_count;
      });
      std::vector<std::uint64_t> labels;
      std::uint64_t filled = 0;
      for (; it != frames.end() && filled < n; ++it) {
        rd.read_frame(std::uint64_t(it - frames.begin()), labels);
        const std::uint64_t from = std::max(start, it->first_tet) - it->first_tet;
        const std::uint64_t to = std::min(stop, it->first_tet + it->tet_count) - it->first_tet;
        std::span<std::uint64_t> part(labels.data() + 4 * from, 4 * (to - from));
        if (original_ids) checked_points().map_to_original(part);
        std::memcpy(out.get() + 4 * filled, part.data(), part.size_bytes());
        filled += to - from;
      }
      if (filled != n)
        throw InputError(rd.path() + ": the frame index does not cover tets " + std::to_string(start) + ".." +
                         std::to_string(stop));
    }
    return to_array(std::move(out), {py::ssize_t(n), 4});
  }

  // The frame index: first tet, tet count, smallest and largest label of each frame.
  py::dict frame_index() const {
    const auto& frames = r().frames();
    const std::size_t f = frames.size();
    Buffer<std::int64_t> first(f), count(f), lo(f), hi(f);
    for (std::size_t k = 0; k < f; ++k) {
      first.get()[k] = std::int64_t(frames[k].first_tet);
      count.get()[k] = std::int64_t(frames[k].tet_count);
      lo.get()[k] = std::int64_t(frames[k].base_label);
      hi.get()[k] = std::int64_t(frames[k].max_label);
    }
    py::dict d;
    d["first_tet"] = to_array(std::move(first), {py::ssize_t(f)});
    d["tet_count"] = to_array(std::move(count), {py::ssize_t(f)});
    d["min_label"] = to_array(std::move(lo), {py::ssize_t(f)});
    d["max_label"] = to_array(std::move(hi), {py::ssize_t(f)});
    return d;
  }

 private:
  std::unique_ptr<io::TetReader> reader_;
  io::PeriodicBox box_;                                 // a periodic container's (offsets_ set)
  std::unique_ptr<io::PeriodicOffsetsReader> offsets_;  // reads reader_'s POFS: declared after it
  mutable std::once_flag points_checked_;
};

// ---- exceptions ----

void register_exceptions(py::module_& m) {
  // Subclasses of the built-in exceptions the brief of each names: code that catches
  // ValueError / OSError keeps working, and code that wants tetstream's own can.
  static py::exception<InputError> input_error(m, "InputError", PyExc_ValueError);
  static py::exception<UsageError> usage_error(m, "UsageError", PyExc_ValueError);
  static py::exception<IoError> io_error(m, "IoError", PyExc_OSError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const pipeline::Interrupted& e) {
      PyErr_SetString(PyExc_KeyboardInterrupt, e.what());
    } catch (const InputError& e) {
      PyErr_SetString(input_error.ptr(), e.what());
    } catch (const UsageError& e) {
      PyErr_SetString(usage_error.ptr(), e.what());
    } catch (const IoError& e) {
      PyErr_SetString(io_error.ptr(), e.what());
    } catch (const Error& e) {  // any other kind, by its exit code
      switch (e.code()) {
        case ExitCode::kInterrupted:
          PyErr_SetString(PyExc_KeyboardInterrupt, e.what());
          break;
        case ExitCode::kIoFailure:
          PyErr_SetString(io_error.ptr(), e.what());
          break;
        case ExitCode::kUsage:
          PyErr_SetString(usage_error.ptr(), e.what());
          break;
        default:
          PyErr_SetString(input_error.ptr(), e.what());
          break;
      }
    }
  });
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  // Each command of the package is one command of the tool: its files are noted, and
  // forgotten when the next one starts (io/output_file.hpp).
  io::note_files(true);
  m.doc() = "tetstream's compiled core; use the package `tetstream` (its functions carry the documentation).";
  register_exceptions(m);
  m.def("delaunay", &delaunay, py::arg("points"), py::arg("index_dtype") = "int64", py::arg("threads") = 0,
        "In-core Delaunay triangulation of a C-contiguous (N, 3) float64 array; a dict of arrays.");
  m.def("run", &run, py::arg("input"), py::arg("more_inputs"), py::arg("output"), py::arg("memory_bytes"),
        py::arg("threads"), py::arg("progress"), py::arg("resume"), py::arg("options"), py::arg("emit") = py::none(),
        "The out-of-core job; its summary as JSON text (what `tetstream run --json` prints).");
  m.def("periodic_tets", &periodic_tets, py::arg("path"),
        "A periodic container's tets: simplices (input indices), offsets (periods), period.");
  m.def("spill", &spill_array, py::arg("path"), py::arg("array"),
        "Writes a C-contiguous array's bytes to PATH (PATH.partial, renamed when complete).");
  m.def("parse_memory", &memory_size, py::arg("memory"), "Bytes of a budget such as '4G', '512M' or an int.");
  m.def("verify", &verify, py::arg("path"), py::arg("memory"), py::arg("sample"), py::arg("seed"), py::arg("tmpdir"),
        py::arg("volume_tolerance"), py::arg("max_listed"), py::arg("progress"), py::arg("threads") = 0,
        py::arg("emit") = py::none(),
        "Verifies a container; the report as JSON text (what `tetstream verify --json` prints).");
  m.def("field", &field, py::arg("input"), py::arg("prefix"), py::arg("density"), py::arg("voronoi"),
        py::arg("neighbours"), py::arg("grid"), py::arg("box"), py::arg("hull"), py::arg("dtype"),
        py::arg("neighbour_int64"), py::arg("mass"), py::arg("memory"), py::arg("tmpdir"), py::arg("progress"),
        py::arg("threads") = 0, py::arg("emit") = py::none(),
        "`tetstream field` on a container: writes PREFIX.*.npy; a summary dict with their paths.");
  m.def("field_sums", &field_sums, py::arg("points"), py::arg("simplices"), py::arg("neighbors"), py::arg("voronoi"),
        py::arg("threads") = 0, "(star volume, Voronoi volume, on hull) per point of an in-memory triangulation.");
  m.def("convert", &convert, py::arg("input"), py::arg("output"), py::arg("binary") = false, py::arg("compress") = 0,
        "A container to a mesh file (`tetstream convert`); the files written.");
  m.def("expand_inputs", &io::expand_inputs, py::arg("paths"),
        "The CLI's input list: a path that is no file and holds * ? [ is a glob, its matches in natural order.");
  m.def("read_points", &read_points, py::arg("path"), "A point file's points as an (N, 3) float64 array.");
  tetstream::python::register_geometry(m);
  m.attr("max_in_core_points") = kMaxInCorePoints;
  py::class_<Reader>(m, "Reader")
      .def(py::init<const std::string&>(), py::arg("path"))
      .def("close", &Reader::close)
      .def_property_readonly("closed", &Reader::closed)
      .def("header", &Reader::header)
      .def("points", &Reader::points, py::arg("first"), py::arg("count"), py::arg("xyz") = true, py::arg("ids") = false)
      .def("frame", &Reader::frame, py::arg("k"), py::arg("original_ids") = false, py::arg("narrow") = false,
           py::arg("release_pages") = false)
      .def("tets", &Reader::tets, py::arg("start"), py::arg("stop"), py::arg("original_ids") = false)
      .def("frame_index", &Reader::frame_index)
      .def("frame_offsets", &Reader::frame_offsets, py::arg("k"));
}
