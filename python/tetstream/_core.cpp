// tetstream._core: the compiled half of the Python package (python/tetstream/__init__.py
// is the public face, with the docstrings and type hints; docs/python.md).
//
//   delaunay(points, index_dtype)  the in-core kernel (core::Delaunay) on an (N, 3) array
//   run(input, output, options)    the out-of-core job (pipeline::run_job), its --json summary
//   Reader(path)                   a .tets container (io::TetReader): points, frames, tets
//   verify(path, ...)              pipeline::verify_file, its --json report
//
// Every long computation runs with the GIL released. Arrays handed to Python are not
// copied: each owns a heap buffer through a capsule (its .base) that frees it.
// Exceptions: tetstream's InputError/UsageError -> ValueError subclasses, IoError ->
// an OSError subclass, Interrupted -> KeyboardInterrupt (see register_exceptions).
#include "core/delaunay.hpp"
#include "core/error.hpp"
#include "core/huge_pages.hpp"
#include "io/point_format.hpp"
#include "io/tet_reader.hpp"
#include "io/output_file.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/run/summary_json.hpp"
#include "pipeline/verify/verify.hpp"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <omp.h>
#include <sys/mman.h>

#include <algorithm>
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

// ---- logging: the pipeline logs through spdlog; here to stderr, like the CLI ----

void configure_logging(bool verbose) {
  static std::shared_ptr<spdlog::logger> logger = [] {
    auto l = spdlog::get("tetstream");
    if (!l) {
      l = spdlog::stderr_color_mt("tetstream");
      l->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
    }
    spdlog::set_default_logger(l);
    return l;
  }();
  spdlog::set_level(verbose ? spdlog::level::info : spdlog::level::warn);
}

// ---- in core: the kernel ----

// Whether the kernel's 32-bit ids hold n points (caller ids below 2^31, tet ids below
// 2^30 at the kernel's estimate of 6.9 tets per point, with some headroom).
constexpr std::size_t kMaxInCorePoints = std::size_t(150'000'000);

template <class I>
py::dict triangulation_arrays(const core::Delaunay& dt, std::size_t n, int threads) {
  // Output index of each finite tet slot: counted per block, then numbered, in parallel.
  const std::size_t slots = dt.num_tet_slots();
  constexpr std::uint32_t kNone = 0xFFFFFFFFu;
  Buffer<I> simplices, neighbors, hull, duplicates;
  std::size_t m = 0, h = 0, d = 0;
  {
    py::gil_scoped_release release;
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
        for (std::size_t t = b * kBlock, e = std::min(slots, t + kBlock); t < e; ++t) ix[t] = finite(t) ? next++ : kNone;
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
        for (int j = 0; j < 4; ++j) s[4 * i + j] = I(dt.vertex(core::TetId(t), j));
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
    // Duplicates: every input point that is not a vertex, and the vertex it merged into.
    for (std::size_t v = 0; v < n; ++v)
      if (dt.incident_tet(core::VertexId(v)) == core::kNoTet) ++d;
    duplicates = Buffer<I>(2 * d);
    I* dp = duplicates.get();
    k = 0;
    for (std::size_t v = 0; v < n; ++v)
      if (dt.incident_tet(core::VertexId(v)) == core::kNoTet) {
        core::VertexId to = dt.duplicate_of(core::VertexId(v));
        // (the first point with these coordinates; follow it to the vertex if need be)
        for (int guard = 0; guard < 64 && dt.incident_tet(to) == core::kNoTet && dt.duplicate_of(to) != to; ++guard)
          to = dt.duplicate_of(to);
        dp[2 * k] = I(v);
        dp[2 * k + 1] = I(to);
        ++k;
      }
  }
  py::dict out;
  out["simplices"] = to_array(std::move(simplices), {py::ssize_t(m), 4});
  out["neighbors"] = to_array(std::move(neighbors), {py::ssize_t(m), 4});
  out["convex_hull"] = to_array(std::move(hull), {py::ssize_t(h), 3});
  out["duplicates"] = to_array(std::move(duplicates), {py::ssize_t(d), 2});
  return out;
}

// points: a C-contiguous (N, 3) float64 array (the Python side converts others).
py::dict delaunay(py::array_t<double, py::array::c_style> points, const std::string& index_dtype, int threads) {
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw UsageError("points must be an (N, 3) array");
  const std::size_t n = std::size_t(points.shape(0));
  if (n > kMaxInCorePoints)
    throw UsageError(std::to_string(n) + " points are more than the in-memory kernel holds (" +
                     std::to_string(kMaxInCorePoints) + "); use tetstream.run(), which works out of core");
  if (index_dtype == "int32" && n > std::size_t(0x7FFFFFFF)) throw UsageError("int32 indices cannot hold N points");
  const double* xyz = points.data();
  auto dt = std::make_unique<core::Delaunay>();
  core::BuildStatus status;
  {
    py::gil_scoped_release release;
    for (std::size_t i = 0; i < 3 * n; ++i)
      if (!std::isfinite(xyz[i]))
        throw InputError("points: row " + std::to_string(i / 3) + ": a coordinate is not finite");
    status = dt->build(xyz, nullptr, n);
  }
  if (status != core::BuildStatus::kOk)
    throw InputError("points: fewer than 4 affinely independent distinct points (" + std::to_string(n) +
                     " given): no tetrahedron");
  const int team = threads > 0 ? threads : omp_get_max_threads();
  py::dict out = index_dtype == "int32" ? triangulation_arrays<std::int32_t>(*dt, n, team)
                                        : triangulation_arrays<std::int64_t>(*dt, n, team);
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
    if (k == "tmpdir") o.tmpdir = get_string(value);
    else if (k == "buffer") o.buffer_spacings = value.cast<double>();
    else if (k == "segment_points" || k == "zone_points") o.segment_points = value.cast<std::uint64_t>();
    else if (k == "zones") {
      const int z = value.cast<int>();
      if (z < 0 || z > 4096) throw UsageError("zones must be in [0, 4096]");
      o.zones = z;
    } else if (k == "sort_run_points") o.sort_run_points = value.cast<std::uint64_t>();
    else if (k == "checkpoint") {
      // True/False, or the directory in which to make the checkpoint.
      if (py::isinstance<py::bool_>(value)) o.checkpoint = value.cast<bool>();
      else o.checkpoint = true, o.checkpoint_dir = get_string(value);
    } else if (k == "force") o.force = value.cast<bool>();
    else if (k == "format") io::parse_format_name(get_string(value), o.read.format, o.read.type);
    else if (k == "type") {
      const std::string t = get_string(value);
      if (t == "f32" || t == "float32") o.read.type = io::ScalarType::kFloat32;
      else if (t == "f64" || t == "float64") o.read.type = io::ScalarType::kFloat64;
      else throw UsageError("type: expected f32 or f64, got '" + t + "'");
    } else if (k == "stride") o.read.stride = value.cast<std::uint64_t>();
    else if (k == "offset") o.read.offset = value.cast<std::uint64_t>();
    else if (k == "byte_order") o.read.byte_order = io::parse_byte_order(get_string(value));
    else if (k == "columns") o.read.columns = value.cast<std::vector<std::uint64_t>>();
    else if (k == "properties") o.read.properties = value.cast<std::vector<std::string>>();
    else if (k == "datasets" || k == "dataset") {
      if (py::isinstance<py::str>(value)) o.read.datasets = {get_string(value)};
      else o.read.datasets = value.cast<std::vector<std::string>>();
    } else {
      throw py::type_error("run() got an unexpected keyword argument '" + k + "'");
    }
  }
}

// Runs `work` on a thread of its own with the GIL released, while this thread wakes up
// ten times a second to let Python run its signal handlers: Ctrl-C (KeyboardInterrupt
// from Python's handler) asks the job to stop (pipeline::request_interrupt), the job
// unwinds through its cleanup (a checkpointed run keeps its checkpoint), and the Python
// exception is raised here once it has.
// One job (run or verify) at a time per process: they share the interrupt flag and
// the log level.
std::mutex g_job_mutex;

template <class R>
R run_interruptible(std::function<R()> work) {
  std::unique_lock<std::mutex> one_job(g_job_mutex, std::try_to_lock);
  if (!one_job.owns_lock())
    throw UsageError("another tetstream.run() or verify() is running in this process: one at a time");
  pipeline::clear_interrupt();
  std::packaged_task<R()> task(std::move(work));
  std::future<R> done = task.get_future();
  std::thread worker(std::move(task));
  std::optional<py::error_already_set> pending;
  for (;;) {
    bool ready;
    {
      py::gil_scoped_release release;
      ready = done.wait_for(std::chrono::milliseconds(100)) == std::future_status::ready;
    }
    if (ready) break;
    if (PyErr_CheckSignals() != 0) {
      pending.emplace();  // fetches (and clears) the Python error
      pipeline::request_interrupt(SIGINT);
      py::gil_scoped_release release;
      done.wait();
      break;
    }
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
                std::uint64_t memory_bytes, int threads, bool progress, bool resume, const py::dict& options) {
  pipeline::RunOptions o;
  o.input = input;
  o.read.more_inputs = more_inputs;
  o.output = output;
  o.memory_bytes = memory_bytes;
  if (threads < 0 || threads > 1024) throw UsageError("threads must be in [1, 1024] (or None: all cores)");
  o.threads = threads;
  o.progress = progress;
  o.resume = resume;
  apply_run_options(o, options);
  if (o.resume && o.force) throw UsageError("resume and force exclude each other");
  if (io::is_std_stream(o.input) || io::is_std_stream(o.output))
    throw UsageError("standard input/output ('-') is for the command line; give file names");
  io::forget_noted_files();  // this job's inputs are noted as it opens them
  return run_interruptible<std::string>([o] {
    configure_logging(o.progress);
    if (o.threads > 0) omp_set_num_threads(o.threads);
    const pipeline::RunSummary s = pipeline::run_job(o);
    return pipeline::run_summary_json(o, s).dump();
  });
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
    throw UsageError(path + ".partial exists: another job is writing this input, or one was killed (remove it if "
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
                   int threads) {
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
  return run_interruptible<std::string>([o, path, threads] {
    configure_logging(o.progress);
    if (threads > 0) omp_set_num_threads(threads);
    return pipeline::verify_report_json(pipeline::verify_file(path, o), path).dump();
  });
}

// ---- reading a container ----

class Reader {
 public:
  explicit Reader(const std::string& path) {
    py::gil_scoped_release release;
    reader_ = std::make_unique<io::TetReader>(path);
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
    return d;
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
      auto it = std::upper_bound(frames.begin(), frames.end(), start,
                                 [](std::uint64_t s, const io::FrameEntry& f) { return s < f.first_tet + f.tet_count; });
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
      if (filled != n) throw InputError(rd.path() + ": the frame index does not cover tets " + std::to_string(start) +
                                        ".." + std::to_string(stop));
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
        case ExitCode::kInterrupted: PyErr_SetString(PyExc_KeyboardInterrupt, e.what()); break;
        case ExitCode::kIoFailure: PyErr_SetString(io_error.ptr(), e.what()); break;
        case ExitCode::kUsage: PyErr_SetString(usage_error.ptr(), e.what()); break;
        default: PyErr_SetString(input_error.ptr(), e.what()); break;
      }
    }
  });
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "tetstream's compiled core; use the package `tetstream` (its functions carry the documentation).";
  register_exceptions(m);
  m.def("delaunay", &delaunay, py::arg("points"), py::arg("index_dtype") = "int64", py::arg("threads") = 0,
        "In-core Delaunay triangulation of a C-contiguous (N, 3) float64 array; a dict of arrays.");
  m.def("run", &run, py::arg("input"), py::arg("more_inputs"), py::arg("output"), py::arg("memory_bytes"),
        py::arg("threads"), py::arg("progress"), py::arg("resume"), py::arg("options"),
        "The out-of-core job; its summary as JSON text (what `tetstream run --json` prints).");
  m.def("spill", &spill_array, py::arg("path"), py::arg("array"),
        "Writes a C-contiguous array's bytes to PATH (PATH.partial, renamed when complete).");
  m.def("parse_memory", &memory_size, py::arg("memory"), "Bytes of a budget such as '4G', '512M' or an int.");
  m.def("verify", &verify, py::arg("path"), py::arg("memory"), py::arg("sample"), py::arg("seed"), py::arg("tmpdir"),
        py::arg("volume_tolerance"), py::arg("max_listed"), py::arg("progress"), py::arg("threads") = 0,
        "Verifies a container; the report as JSON text (what `tetstream verify --json` prints).");
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
      .def("frame_index", &Reader::frame_index);
}
