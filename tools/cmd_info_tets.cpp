// `tetstream info OUT.tets`: what a container holds, what it costs, and how it was made.
// Reads only the header, index and footer (the open checks them), so it is instant on
// any size of file; `--check` also reads every point and frame and checks their CRCs.
// A periodic container (docs/periodic.md) shows its box; --check decodes its offsets.
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/util/progress.hpp"
#include "tools/info_tets.hpp"

#include <charconv>
#include <optional>
#include <cstdio>
#include <string>
#include <vector>

namespace tetstream::cli {

namespace {
std::string shortest(double v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}
}  // namespace

void info_tets(const std::string& path, Context& ctx, bool check) {
  const io::TetReader r(path, io::TetReader::Periodic::kAccept);
  std::optional<io::PeriodicBox> box;
  std::optional<io::PeriodicOffsetsReader> offsets;
  if (r.periodic()) {
    box = io::parse_periodic_box(r.section(io::kTagPeriodicBox), path);
    offsets.emplace(r);
  }
  if (check) {
    // Everything a reader relies on: the points' CRC, each frame's CRC and decoding
    // (and a periodic frame's offsets: their CRC, decoding and count).
    r.verify_points();
    pipeline::Progress progress("checking", "frames", r.frame_count(), !ctx.global.quiet);
    std::vector<std::uint64_t> labels;
    std::vector<std::uint16_t> codes;
    for (std::uint64_t k = 0; k < r.frame_count(); ++k) {
      r.read_frame(k, labels);
      if (offsets) offsets->read(k, codes);
      progress.add(1);
    }
    progress.finish();
  }
  const io::TetFileHeader& h = r.header();
  const std::uint64_t tets = r.tet_count();
  const double per_tet = tets ? double(r.tet_bytes()) / double(tets) : 0.0;
  const double file_per_tet = tets ? double(r.file_bytes()) / double(tets) : 0.0;
  const char* coords = h.coord_type == io::CoordType::kFloat32 ? "float32" : "float64";
  const std::string version = std::to_string(r.version_major()) + "." + std::to_string(r.version_minor());

  nlohmann::json options = nlohmann::json::parse(h.options, nullptr, false);
  if (options.is_discarded()) options = h.options;

  if (!ctx.global.json) {
    std::printf("file:     %s\n", path.c_str());
    std::printf("format:   .tets container %s\n", version.c_str());
    std::printf("points:   %llu (%s coordinates, %u-bit original indices",
                static_cast<unsigned long long>(h.point_count), coords, h.id_width);
    if (h.input_count) std::printf(", %llu input points", static_cast<unsigned long long>(h.input_count));
    std::printf(")\n");
    std::printf("tets:     %llu in %llu frames (%u-bit labels), %.2f per point\n",
                static_cast<unsigned long long>(tets), static_cast<unsigned long long>(r.frame_count()), h.label_width,
                h.point_count ? double(tets) / double(h.point_count) : 0.0);
    std::printf("size:     %s; tets %s = %.3f bytes per tet (%.1fx smaller than 16 raw)\n",
                pipeline::human_bytes(double(r.file_bytes())).c_str(),
                pipeline::human_bytes(double(r.tet_bytes())).c_str(), per_tet, per_tet > 0 ? 16.0 / per_tet : 0.0);
    for (int c = 0; c < 3; ++c) {
      std::printf("%s:        [%s, %s]\n",
                  c == 0   ? "x"
                  : c == 1 ? "y"
                           : "z",
                  shortest(h.bbox_min[c]).c_str(), shortest(h.bbox_max[c]).c_str());
    }
    if (box) {
      std::printf(
          "periodic: the flat torus [0, %s) x [0, %s) x [0, %s) (each tet's vertex offsets in POFS; "
          "sort axis %c)\n",
          shortest(box->period[0]).c_str(), shortest(box->period[1]).c_str(), shortest(box->period[2]).c_str(),
          "xyz"[box->sort_axis]);
    }
    std::printf("made by:  %s\n", h.tool.empty() ? "(unknown)" : h.tool.c_str());
    std::printf("options:  %s\n", h.options.empty() ? "(none)" : h.options.c_str());
    std::printf("checked:  %s\n", check ? "header, index, footer, every point and frame (CRCs, decoding)"
                                        : "header, index, footer (--check reads the points and frames too)");
    std::fflush(stdout);
  }
  ctx.summary = {{"command", "info"},
                 {"file", path},
                 {"format", "tets"},
                 {"version", version},
                 {"points", h.point_count},
                 {"input_points", h.input_count},
                 {"coord_type", coords},
                 {"label_width", h.label_width},
                 {"id_width", h.id_width},
                 {"tets", tets},
                 {"frames", r.frame_count()},
                 {"bytes", r.file_bytes()},
                 {"tet_bytes", r.tet_bytes()},
                 {"bytes_per_tet", per_tet},
                 {"file_bytes_per_tet", file_per_tet},
                 {"bbox",
                  {{"min", {h.bbox_min[0], h.bbox_min[1], h.bbox_min[2]}},
                   {"max", {h.bbox_max[0], h.bbox_max[1], h.bbox_max[2]}}}},
                 {"tool", h.tool},
                 {"options", options},
                 {"checked", check ? "all" : "header"}};
  if (box) ctx.summary["periodic"] = {{"period", box->period}, {"sort_axis", box->sort_axis}};
}

}  // namespace tetstream::cli
