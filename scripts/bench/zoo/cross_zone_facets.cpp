// The facets of a triangulation whose two tets are written by different zones: what a
// certificate that matches facets across zones (the Delaunay lemma, as `verify`
// checks it) would have to pair and test, one insphere a facet.
//
//   cross_zone_facets POINTS.f64 TETS.u32 ZONES.log
//
// POINTS: `tetstream cat --points --format f64` (label order); TETS: `tetstream cat
// --format u32`; ZONES: the "zone [a, b) strip [lo, hi) on k round 1:" lines of the
// job's `--log-level debug` (its zones and their exact strips). A tet is written by the
// zone of its smallest label (docs/certificate.md, Invariant 2). Prints one JSON line.
// Holds 40 bytes a tet: for 10^6-10^7 points.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <regex>
#include <string>
#include <vector>

namespace {

struct Zone {
  std::uint64_t begin, end;
  double lo, hi;
  int axis;  // -1: the whole segment
};

template <class T>
std::vector<T> read_all(const char* path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::cerr << path << ": cannot open\n";
    std::exit(2);
  }
  in.seekg(0, std::ios::end);
  std::vector<T> v(std::size_t(in.tellg()) / sizeof(T));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(v.data()), std::streamsize(v.size() * sizeof(T)));
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::cerr << "usage: cross_zone_facets POINTS.f64 TETS.u32 ZONES.log\n";
    return 2;
  }
  const std::vector<double> xyz = read_all<double>(argv[1]);
  const std::vector<std::uint32_t> tets = read_all<std::uint32_t>(argv[2]);
  const std::size_t n = xyz.size() / 3, t = tets.size() / 4;
  if (n >= (std::size_t(1) << 21)) {  // a facet's three labels are packed in 21 bits each
    std::cerr << "cross_zone_facets: at most 2^21 points\n";
    return 2;
  }
  std::vector<Zone> zones;
  {
    std::ifstream log(argv[3]);
    const std::regex line(R"(zone \[(\d+), (\d+)\) strip \[([^,]+), ([^)]+)\) on ([xyz-]) round 1:)");
    std::string s;
    std::smatch m;
    while (std::getline(log, s))
      if (std::regex_search(s, m, line)) {
        const char a = m[5].str()[0];
        zones.push_back({std::stoull(m[1]), std::stoull(m[2]), std::strtod(m[3].str().c_str(), nullptr),
                         std::strtod(m[4].str().c_str(), nullptr), a == '-' ? -1 : a - 'x'});
      }
  }
  std::sort(zones.begin(), zones.end(),
            [](const Zone& a, const Zone& b) { return a.begin != b.begin ? a.begin < b.begin : a.lo < b.lo; });
  zones.erase(std::unique(zones.begin(), zones.end(),
                          [](const Zone& a, const Zone& b) { return a.begin == b.begin && a.lo == b.lo; }),
              zones.end());
  // A label's zone: its segment's strip that holds its coordinate ([lo, hi), as the job's).
  std::vector<int> zone_of(n, -1);
  for (std::size_t z = 0; z < zones.size(); ++z)
    for (std::uint64_t l = zones[z].begin; l < zones[z].end && l < n; ++l)
      if (zones[z].axis < 0 || (xyz[3 * l + zones[z].axis] >= zones[z].lo && xyz[3 * l + zones[z].axis] < zones[z].hi))
        zone_of[l] = int(z);
  const long unplaced = std::count(zone_of.begin(), zone_of.end(), -1);
  // Every facet (its three labels, 21 bits each) with its tet; a facet met twice is interior.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> facets;
  facets.reserve(4 * t);
  std::vector<int> writer(t);
  for (std::size_t i = 0; i < t; ++i) {
    const std::uint32_t* v = &tets[4 * i];
    writer[i] = zone_of[*std::min_element(v, v + 4)];
    for (int k = 0; k < 4; ++k) {
      std::uint32_t f[3];
      for (int r = 0, j = 0; r < 4; ++r)
        if (r != k) f[j++] = v[r];
      std::sort(f, f + 3);
      facets.push_back({std::uint64_t(f[0]) << 42 | std::uint64_t(f[1]) << 21 | f[2], std::uint32_t(i)});
    }
  }
  std::sort(facets.begin(), facets.end());
  std::uint64_t interior = 0, cross = 0, hull = 0;
  std::vector<char> touches(t, 0);
  for (std::size_t i = 0; i < facets.size();) {
    if (i + 1 < facets.size() && facets[i + 1].first == facets[i].first) {
      ++interior;
      const std::uint32_t a = facets[i].second, b = facets[i + 1].second;
      if (writer[a] != writer[b]) ++cross, touches[a] = touches[b] = 1;
      i += 2;
    } else {
      ++hull, ++i;
    }
  }
  const long with_cross = std::count(touches.begin(), touches.end(), 1);
  std::printf(
      "{\"points\": %zu, \"tets\": %zu, \"zones\": %zu, \"unplaced_points\": %ld, \"interior_facets\": %llu, "
      "\"hull_facets\": %llu, \"cross_zone_facets\": %llu, \"cross_zone_facets_per_point\": %.4f, "
      "\"tets_with_a_cross_zone_facet\": %ld}\n",
      n, t, zones.size(), unplaced, (unsigned long long)interior, (unsigned long long)hull, (unsigned long long)cross,
      double(cross) / double(std::max<std::size_t>(n, 1)), with_cross);
  return 0;
}
