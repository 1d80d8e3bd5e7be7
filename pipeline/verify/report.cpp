// verify's options and report: names of the violations, validation, the summary.
#include "pipeline/verify/verify.hpp"

#include "core/error.hpp"
#include "pipeline/util/progress.hpp"

#include <sstream>
#include <string>

namespace tetstream::pipeline {

const char* violation_name(Violation v) {
  switch (v) {
    case Violation::kStorage:
      return "storage";
    case Violation::kOrientation:
      return "orientation";
    case Violation::kDuplicateTet:
      return "duplicate_tet";
    case Violation::kFacetOverused:
      return "facet_overused";
    case Violation::kFacetSameSide:
      return "facet_same_side";
    case Violation::kDelaunay:
      return "delaunay";
    case Violation::kHullOpen:
      return "hull_open";
    case Violation::kHullConvex:
      return "hull_convex";
    case Violation::kHullTopology:
      return "hull_topology";
    case Violation::kMissingPoint:
      return "missing_point";
    case Violation::kEuler:
      return "euler";
    case Violation::kVolume:
      return "volume";
    case Violation::kCount:
      break;
  }
  return "?";
}

void VerifyOptions::validate() const {
  if (!(sample > 0.0) || sample > 1.0) throw UsageError("--sample must be in (0, 1]");
  if (memory_bytes < (std::uint64_t(16) << 20)) throw UsageError("--memory must be at least 16M");
  if (!(volume_tolerance >= 0.0)) throw UsageError("the volume tolerance must be >= 0");
  if (batch_tets == 0) throw UsageError("batch_tets must be at least 1");
}

std::uint64_t VerifyReport::violations() const {
  std::uint64_t n = 0;
  for (std::uint64_t c : counts) n += c;
  return n;
}

std::string VerifyReport::summary() const {
  std::ostringstream s;
  s << (ok() ? "VALID" : "INVALID");
  if (sampled) s << " (sample " << sample << ")";
  s << ": " << points << " points, " << tets << " tets";
  if (ok() && !sampled) s << " are the Delaunay triangulation of the points";
  s << "\n";
  s << "  vertices " << vertices << ", facets " << facets << " (" << interior_facets << " interior, " << boundary_facets
    << (sampled ? " unpaired in the sample" : " on the hull") << ")";
  if (!sampled) {
    s << ", edges " << edges << ", V-E+F-T " << euler << "\n";
    s << "  hull: " << hull_vertices << " vertices, " << hull_edges << " edges, V-E+F " << hull_euler
      << "; volume: tets " << tet_volume << ", hull " << hull_volume << ", relative difference " << volume_rel_error;
  }
  s << "\n  checked: " << tets_checked << " tets (orient3d), " << facets_checked << " facets, " << insphere_tests
    << " insphere, " << hull_tests << " hull edge tests";
  if (spilled_records) s << "; spilled " << spilled_records << " records (" << human_bytes(double(spill_bytes)) << ")";
  s << "\n  violations: " << violations();
  for (int k = 0; k < kViolationKinds; ++k)
    if (counts[std::size_t(k)]) s << ", " << violation_name(Violation(k)) << " " << counts[std::size_t(k)];
  for (const Listed& l : listed) s << "\n  " << violation_name(l.kind) << ": " << l.text;
  return s.str();
}

}  // namespace tetstream::pipeline
