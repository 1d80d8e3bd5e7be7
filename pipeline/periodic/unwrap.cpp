#include "pipeline/periodic/unwrap.hpp"

#include "core/error.hpp"
#include "io/tet_container.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <algorithm>

namespace tetstream::pipeline::periodic {

namespace {
// Every stored tet with its vertices as (label, offset code) pairs.
template <class Visit>
void for_each_keyed(const io::TetReader& r, Visit&& visit) {
  const io::PeriodicOffsetsReader offsets(r);
  for_each_stored_tet(r, offsets, [&](const KeptTet& t, std::uint64_t, std::size_t) {
    int c[3];
    io::tet_offset_codes(t.code, c);
    const std::uint64_t key[4] = {t.v[0] * 27 + io::kZeroOffsetCode, t.v[1] * 27 + std::uint64_t(c[0]),
                                  t.v[2] * 27 + std::uint64_t(c[1]), t.v[3] * 27 + std::uint64_t(c[2])};
    visit(key);
  });
}
}  // namespace

Unwrapped unwrap_periodic(const std::string& container, const std::string& dir) {
  const io::TetReader r(container, io::TetReader::Periodic::kAccept);
  r.verify_points();
  const io::PeriodicBox box = io::parse_periodic_box(r.section(io::kTagPeriodicBox), container);
  const std::uint64_t n = r.point_count();
  // The images the tets use, as label * 27 + offset code, sorted: mesh point n + j.
  std::vector<std::uint64_t> images;
  for_each_keyed(r, [&](const std::uint64_t* key) {
    for (int j = 1; j < 4; ++j)
      if (key[j] % 27 != io::kZeroOffsetCode) images.push_back(key[j]);
  });
  std::sort(images.begin(), images.end());
  images.erase(std::unique(images.begin(), images.end()), images.end());

  std::vector<double> xyz(3 * (n + images.size()));
  std::vector<std::uint64_t> ids(n + images.size());
  r.read_points(0, n, xyz.data(), ids.data());
  Unwrapped out;
  out.images = images.size();
  out.point_data = {{"image", std::vector<double>(n + images.size(), 0.0)},
                    {"periodic_label", std::vector<double>(n + images.size(), 0.0)}};
  for (std::uint64_t i = 0; i < n; ++i) out.point_data[1].values[i] = double(i);
  for (std::size_t j = 0; j < images.size(); ++j) {
    const std::uint64_t label = images[j] / 27;
    int o[3];
    io::offset_of_code(int(images[j] % 27), o);
    for (int k = 0; k < 3; ++k) xyz[3 * (n + j) + k] = xyz[3 * label + k] + o[k] * box.period[k];
    ids[n + j] = r.header().input_count + j;  // beyond every input index: not an input point
    out.point_data[0].values[n + j] = 1.0;
    out.point_data[1].values[n + j] = double(label);
  }
  io::TetFileHeader h;
  h.point_count = n + images.size();
  h.input_count = r.header().input_count + images.size();
  h.tool = r.header().tool;
  h.options = r.header().options;
  for (int k = 0; k < 3; ++k) {
    h.bbox_min[k] = -box.period[k];
    h.bbox_max[k] = 2 * box.period[k];
  }
  out.container = dir + "/periodic-unwrapped.tets";
  io::TetWriterOptions wo;
  wo.sync = false;
  io::TetWriter w(out.container, h, wo);
  w.add_points(xyz.data(), ids.data(), ids.size());
  std::vector<std::uint64_t> tets;
  for_each_keyed(r, [&](const std::uint64_t* key) {
    for (int j = 0; j < 4; ++j) {
      const bool image = key[j] % 27 != io::kZeroOffsetCode;
      tets.push_back(image ? n + std::uint64_t(std::lower_bound(images.begin(), images.end(), key[j]) - images.begin())
                           : key[j] / 27);
    }
    if (tets.size() >= 4 * (std::size_t(1) << 18)) {
      w.add_tets(std::span<const std::uint64_t>(tets));
      tets.clear();
    }
  });
  if (!tets.empty()) w.add_tets(std::span<const std::uint64_t>(tets));
  w.finish();
  return out;
}

}  // namespace tetstream::pipeline::periodic
