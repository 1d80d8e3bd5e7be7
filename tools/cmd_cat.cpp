// `tetstream cat OUT.tets`: the tets (or points) of a container on stdout, for pipes.
//
//   --format text   "a b c d\n" per tet (default)
//   --format u32    4 little-endian uint32 per tet, no header
//   --format u64    4 little-endian uint64 per tet
//   --original-ids  indices in the user's input order instead of labels (sorted order)
//   --frames A:B    frames A..B-1 only (Python slice: "A:", ":B", "K" for one frame)
//   --points        the points instead: "x y z original_id\n" per label, in label order;
//                   with --format f64, 3 little-endian float64 per point (a raw .f64 file)
//
// A periodic container (docs/periodic.md): "a b c d  bx by bz  cx cy cz  dx dy dz\n"
// per tet, text only: the vertices and the offsets (in periods, each -1, 0 or 1) of b,
// c and d relative to a (POFS, docs/format.md §6); --points as for any container.
//
// Quiet by default, as a filter should be: no progress and no log line unless -v.
// The --json summary goes to stderr (or --json-file), never between the tets.
//
// Streams frame by frame in bounded memory. Tets come in stored order (docs/format.md
// §4.1), each positively oriented. FILE "-" reads the container from standard input as
// it is written (`run ... -o - | cat -`): each frame is checked before it is printed,
// and the exit status says whether the stream was complete (index and footer agree).
#include "core/error.hpp"
#include "io/output_file.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_stream_reader.hpp"
#include "pipeline/util/progress.hpp"
#include "tools/command.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <vector>
#include <unistd.h>

namespace tetstream::cli {
namespace {

struct CatArgs {
  std::string path;
  std::string format = "text";
  bool original_ids = false;
  std::string frames;
  bool points = false;
};

// Parses "A:B", "A:", ":B", ":" or "K" against `count` frames into [first, last).
std::pair<std::uint64_t, std::uint64_t> parse_frames(const std::string& spec, std::uint64_t count) {
  auto number = [&spec](const std::string& s, std::uint64_t fallback) {
    if (s.empty()) return fallback;
    std::uint64_t v = 0;
    const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || p != s.data() + s.size()) throw UsageError("--frames: bad range '" + spec + "'");
    return v;
  };
  std::uint64_t a = 0, b = count;
  const auto colon = spec.find(':');
  if (colon == std::string::npos) {
    a = number(spec, 0);
    b = a + 1;
  } else {
    a = number(spec.substr(0, colon), 0);
    b = number(spec.substr(colon + 1), count);
  }
  if (a > b || b > count) {
    throw UsageError("--frames " + spec + ": the file has frames 0.." + std::to_string(count) + " (exclusive end)");
  }
  return {a, b};
}

// A filter reports progress only when asked (-v, and not -q).
bool reports(const Context& ctx) { return ctx.global.verbose && !ctx.global.quiet; }

// Buffered stdout; a write error (full disk, closed pipe) is an IoError.
class Stdout {
 public:
  Stdout() : buf_(new char[kSize]) {}
  char* reserve(std::size_t n) {
    if (used_ + n > kSize) flush();
    return buf_.get() + used_;
  }
  void advance(std::size_t n) { used_ += n; }
  void write(const void* p, std::size_t n) {
    if (n > kSize - used_) flush();
    if (n >= kSize) {
      put(p, n);
      return;
    }
    std::memcpy(buf_.get() + used_, p, n);
    used_ += n;
  }
  void flush() {
    put(buf_.get(), used_);
    used_ = 0;
  }

 private:
  static constexpr std::size_t kSize = std::size_t(1) << 20;
  static void put(const void* p, std::size_t n) {
    if (n && std::fwrite(p, 1, n, stdout) != n)
      throw IoError("stdout: write failed: " + std::string(std::strerror(errno)));
  }
  std::unique_ptr<char[]> buf_;
  std::size_t used_ = 0;
};

// One frame's tets (4 values each) in the chosen format.
void write_tets(const std::vector<std::uint64_t>& labels, const std::string& format, Stdout& out,
                std::vector<std::uint32_t>& narrow) {
  if (format == "text") {
    for (std::size_t i = 0; i < labels.size(); i += 4) {
      char* s = out.reserve(96);
      char* e = s;
      for (int c = 0; c < 4; ++c) {
        e = std::to_chars(e, s + 96, labels[i + c]).ptr;
        *e++ = c == 3 ? '\n' : ' ';
      }
      out.advance(std::size_t(e - s));
    }
  } else if (format == "u32") {
    narrow.assign(labels.begin(), labels.end());
    out.write(narrow.data(), 4 * narrow.size());
  } else {
    out.write(labels.data(), 8 * labels.size());
  }
}

// A periodic frame as text: each tet's four vertices, then the offsets of its last
// three relative to its first (io/tet_periodic.hpp).
void write_periodic_tets(const std::vector<std::uint64_t>& labels, const std::vector<std::uint16_t>& codes,
                         Stdout& out) {
  for (std::size_t t = 0; t < codes.size(); ++t) {
    char* s = out.reserve(160);
    char* e = s;
    for (int c = 0; c < 4; ++c) {
      e = std::to_chars(e, s + 160, labels[4 * t + std::size_t(c)]).ptr;
      *e++ = ' ';
    }
    int vertex[3];
    io::tet_offset_codes(codes[t], vertex);
    for (int v = 0; v < 3; ++v) {
      int o[3];
      io::offset_of_code(vertex[v], o);
      for (int k = 0; k < 3; ++k) {
        *e++ = ' ';
        e = std::to_chars(e, s + 160, o[k]).ptr;
      }
    }
    *e++ = '\n';
    out.advance(std::size_t(e - s));
  }
}

// `cat -`: the container read front to back from a pipe as its writer writes it.
void run_cat_stream(const CatArgs& args, Context& ctx) {
  if (args.points || !args.frames.empty()) throw UsageError("cat -: --points and --frames need a container file");
  io::TetStreamReader r(STDIN_FILENO, "standard input", args.original_ids);
  const std::uint64_t top = args.original_ids ? std::max(r.header().input_count, r.point_count()) : r.point_count();
  if (args.format == "u32" && top > (std::uint64_t(1) << 32))
    throw UsageError("values do not fit 32 bits: use --format u64");
  Stdout out;
  std::vector<std::uint64_t> labels;
  std::vector<std::uint32_t> narrow;
  while (r.next_frame(labels)) {
    if (args.original_ids) r.map_to_original(labels);
    write_tets(labels, args.format, out, narrow);
  }
  out.flush();
  if (std::fflush(stdout) != 0) throw IoError("stdout: write failed: " + std::string(std::strerror(errno)));
  ctx.summary = {{"command", "cat"},          {"file", "-"},
                 {"format", args.format},     {"tets", r.tets_read()},
                 {"frames", r.frames_read()}, {"original_ids", args.original_ids}};
}

void run_cat(const CatArgs& args, Context& ctx) {
  ctx.stdout_is_data = true;
  if (args.format == "f64" && !args.points) throw UsageError("--format f64 is for --points; tets are text, u32 or u64");
  if (args.path == "-") return run_cat_stream(args, ctx);
  const io::TetReader r(args.path, io::TetReader::Periodic::kAccept);
  io::refuse_stdout_into_input();
  std::optional<io::PeriodicOffsetsReader> offsets;
  if (r.periodic() && !args.points) {
    if (args.format != "text")
      throw UsageError(args.path + " is periodic: its tets carry vertex offsets and are written as text only");
    offsets.emplace(r);
  }
  // Points and original ids are trusted only after the points' CRC (frames are
  // checked one by one as they are read).
  if (args.points || args.original_ids) r.verify_points();
  const auto [first, last] = parse_frames(args.frames.empty() ? ":" : args.frames, r.frame_count());
  Stdout out;
  std::uint64_t written = 0;

  if (args.points) {
    if (args.format != "text" && args.format != "f64") {
      throw UsageError("--points --format " + args.format + ": points are text or f64 (3 little-endian float64 each)");
    }
    if (!args.frames.empty()) throw UsageError("--points and --frames do not go together");
    const bool binary = args.format == "f64";
    pipeline::Progress progress("cat", "points", r.point_count(), reports(ctx));
    constexpr std::size_t kChunk = 1 << 16;
    std::vector<double> xyz(3 * kChunk);
    std::vector<std::uint64_t> ids(kChunk);
    for (std::uint64_t p = 0; p < r.point_count(); p += kChunk) {
      const std::size_t n = std::size_t(std::min<std::uint64_t>(kChunk, r.point_count() - p));
      r.read_points(p, n, xyz.data(), ids.data());
      if (binary) {
        static_assert(std::endian::native == std::endian::little, "f64 output is little-endian");
        out.write(xyz.data(), 24 * n);
        progress.add(n);
        written += n;
        continue;
      }
      for (std::size_t i = 0; i < n; ++i) {
        char* s = out.reserve(128);
        char* e = s;
        for (int c = 0; c < 3; ++c) {
          e = std::to_chars(e, s + 128, xyz[3 * i + c]).ptr;
          *e++ = ' ';
        }
        e = std::to_chars(e, s + 128, ids[i]).ptr;
        *e++ = '\n';
        out.advance(std::size_t(e - s));
      }
      progress.add(n);
      written += n;
    }
    out.flush();
    if (std::fflush(stdout) != 0) throw IoError("stdout: write failed: " + std::string(std::strerror(errno)));
    progress.finish();
    ctx.summary = {{"command", "cat"}, {"file", args.path}, {"format", args.format}, {"points", written}};
    return;
  }

  // A 32-bit output must hold every value: decide before writing anything.
  if (args.format == "u32") {
    const std::uint64_t top = args.original_ids
                                  ? std::max(r.header().input_count, r.point_count())
                                  : (first < last ? std::max_element(
                                                        r.frames().begin() + first, r.frames().begin() + last,
                                                        [](const auto& a, const auto& b) {
                                                          return a.max_label < b.max_label;
                                                        })->max_label +
                                                        1
                                                  : 0);
    if (top > (std::uint64_t(1) << 32)) throw UsageError("values do not fit 32 bits: use --format u64");
  }

  std::uint64_t total = 0;
  for (std::uint64_t k = first; k < last; ++k) total += r.frames()[k].tet_count;
  pipeline::Progress progress("cat", "tets", total, reports(ctx));
  std::vector<std::uint64_t> labels;
  std::vector<std::uint32_t> narrow;
  std::vector<std::uint16_t> codes;
  for (std::uint64_t k = first; k < last; ++k) {
    r.read_frame(k, labels);
    if (args.original_ids) r.map_to_original(labels);
    if (offsets) {
      offsets->read(k, codes);
      write_periodic_tets(labels, codes, out);
    } else {
      write_tets(labels, args.format, out, narrow);
    }
    written += labels.size() / 4;
    progress.add(labels.size() / 4);
  }
  out.flush();
  if (std::fflush(stdout) != 0) throw IoError("stdout: write failed: " + std::string(std::strerror(errno)));
  progress.finish();
  ctx.summary = {{"command", "cat"}, {"file", args.path},       {"format", args.format},
                 {"tets", written},  {"frames", {first, last}}, {"original_ids", args.original_ids}};
}

void setup_cat(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<CatArgs>();
  CLI::App* cmd = app.add_subcommand("cat",
                                     "Write a .tets container's tets (or points) to stdout, for pipes\n"
                                     "(quiet unless -v; --json goes to stderr)");
  cmd->add_option("file", args->path, ".tets container, or - to read one from standard input as it is written")
      ->required();
  cmd->add_option("--format", args->format,
                  "text (\"a b c d\" per line), u32 or u64 (4 little-endian labels per tet);\n"
                  "with --points: text or f64 (3 little-endian float64 per point)")
      ->check(CLI::IsMember({"text", "u32", "u64", "f64"}))
      ->capture_default_str();
  cmd->add_flag("--original-ids", args->original_ids,
                "Vertex indices in the original input order instead of labels (sorted order)");
  cmd->add_option("--frames", args->frames, "Frames A:B (0-based, end exclusive; 'A:', ':B', or K for one frame)");
  cmd->add_flag("--points", args->points, "Print the points instead: \"x y z original_id\" per label");
  cmd->callback([args, &ctx] { run_cat(*args, ctx); });
}

TETSTREAM_COMMAND(50, setup_cat);

}  // namespace
}  // namespace tetstream::cli
