#include "pipeline/run/summary_json.hpp"

namespace tetstream::pipeline {

nlohmann::json run_summary_json(const RunOptions& o, const RunSummary& s) {
  const double tets_per_s = s.seconds_total > 0 ? double(s.tets) / s.seconds_total : 0;
  nlohmann::json j = {
      {"command", "run"},
      {"input", o.input},
      {"output", o.output},
      {"input_points", s.input_points},
      {"points", s.points},
      {"duplicates", s.duplicates},
      {"axis", std::string(1, "xyz"[s.axis])},
      {"hull_vertices", s.hull_vertices},
      {"segments", s.segments},
      {"zones", s.zones},
      {"window_points", s.window_points},
      {"repair_points", s.repair_points},
      {"range_failures", s.range_failures},
      {"queries", s.queries},
      {"query_points", s.query_points},
      {"query_region_releases", s.query_region_releases},
      {"redundant_ratio", s.redundant_ratio()},
      {"redundant_points",
       {{"segment_buffers", s.segment_buffer_points},
        {"zone_buffers", s.zone_buffer_points},
        {"hull", s.hull_window_points},
        {"neighbours", s.neighbour_points},
        {"repairs", s.repair_points}}},
      {"zone_buffer_share", s.zone_buffer_share()},
      {"tets", s.tets},
      {"certified",
       {{"by_range_test", s.tets - s.tets_by_query - s.tets_by_wall - s.tets_by_rim - s.tets_by_neighbour},
        {"by_query", s.tets_by_query},
        {"by_wall", s.tets_by_wall},
        {"by_rim", s.tets_by_rim},
        {"by_neighbour", s.tets_by_neighbour}}},
      {"rim_rechecks", s.rim_rechecks},
      {"queries_spared", s.queries_spared},
      // The queries that found no conflict, by how far past the window's keys along
      // the sort axis their tets' clipped balls reached, in segment widths.
      {"empty_query_reach",
       {{"within_window_keys", s.empty_reach_none},
        {"under_half_segment", s.empty_reach_half},
        {"under_one_segment", s.empty_reach_one},
        {"under_two_segments", s.empty_reach_two},
        {"farther", s.empty_reach_farther}}},
      {"rim_published", s.rim_published},
      {"rim_no_room", s.rim_no_room},
      {"rim_from_neighbours", s.rim_from_neighbours},
      {"output_bytes", s.output_bytes},
      {"disk_planned_bytes", s.disk_planned_bytes},
      {"disk_peak_bytes", s.disk_peak_bytes},
      {"memory_peak_bytes", s.memory_peak_bytes},
      {"tet_bytes", s.tet_bytes},
      {"bytes_per_tet", s.tets ? double(s.tet_bytes) / double(s.tets) : 0.0},
      {"seconds",
       {{"sort", s.seconds_sort},
        {"index", s.seconds_index},
        {"segments_summed", s.seconds_segments},
        {"segments_build_summed", s.seconds_build},
        {"segments_check_summed", s.seconds_check},
        {"triangulate", s.seconds_triangulate},
        {"write", s.seconds_write},
        {"writer_thread_busy", s.seconds_writer_busy},
        {"waiting_for_writer", s.seconds_writer_wait},
        {"total", s.seconds_total}}},
      {"tets_per_second", tets_per_s},
      {"resumed", s.resumed},
      {"segments_resumed", s.segments_resumed}};
  // The ledger's shares, by phase: what this input was planned to take of --memory
  // (pipeline/memory_budget.hpp).
  nlohmann::json memory = {{"ceiling", s.memory_ceiling}};
  for (const MemoryBudget::Share& share : s.memory_shares) memory[share.phase][share.name] = share.bytes;
  j["memory_planned"] = memory;
  // Each stage's wall time and busy thread-seconds: a stage whose busy / wall stays
  // near 1 on many threads is a serial one (scripts/bench-threads reads these).
  nlohmann::json stages = nlohmann::json::object();
  for (const auto& [name, t] : s.stages)
    stages[name] = {{"wall_seconds", t.wall}, {"busy_thread_seconds", t.busy}, {"parallelism", t.parallelism()}};
  j["stages"] = stages;
  if (!s.ranks.empty()) {
    nlohmann::json ranks = nlohmann::json::array();
    for (const RunSummary::Rank& r : s.ranks)
      ranks.push_back(
          {{"rank", ranks.size()},
           {"labels", {r.first_label, r.end_label}},
           {"segments", r.segments},
           {"zones", r.zones},
           {"tets", r.tets},
           {"frame_bytes", r.frame_bytes},
           {"message_bytes", r.message_bytes},
           {"expected_cost_share", r.expected_cost_share},
           {"seconds",
            {{"index", r.seconds_index}, {"triangulate", r.seconds_triangulate}, {"write", r.seconds_write}}}});
    j["ranks"] = ranks;
  }
  return j;
}

nlohmann::json verify_report_json(const VerifyReport& r, const std::string& path) {
  nlohmann::json counts = nlohmann::json::object();
  for (int k = 0; k < kViolationKinds; ++k) counts[violation_name(Violation(k))] = r.counts[std::size_t(k)];
  nlohmann::json listed = nlohmann::json::array();
  for (const auto& l : r.listed)
    listed.push_back({{"kind", violation_name(l.kind)}, {"where", l.where}, {"text", l.text}});
  nlohmann::json j = {{"command", "verify"},
                      {"input", path},
                      {"valid", r.ok()},
                      {"sampled", r.sampled},
                      {"sample", r.sample},
                      {"points", r.points},
                      {"tets", r.tets},
                      {"vertices", r.vertices},
                      {"facets", r.facets},
                      {"interior_facets", r.interior_facets},
                      {"boundary_facets", r.boundary_facets},
                      {"violations", r.violations()},
                      {"violation_counts", counts},
                      {"listed", listed},
                      {"checked",
                       {{"tets", r.tets_checked},
                        {"facets", r.facets_checked},
                        {"orient3d", r.orient_tests},
                        {"insphere", r.insphere_tests},
                        {"hull_tests", r.hull_tests}}},
                      {"peak_open_facets", r.peak_open_facets},
                      {"peak_open_edges", r.peak_open_edges},
                      {"spilled_records", r.spilled_records},
                      {"spill_bytes", r.spill_bytes},
                      {"memory_planned", r.memory_planned},
                      {"step_tets", r.step_tets},
                      {"seconds", r.seconds}};
  if (!r.sampled) {
    j["edges"] = r.edges;
    j["euler"] = r.euler;
    j["hull"] = {
        {"vertices", r.hull_vertices}, {"edges", r.hull_edges}, {"facets", r.boundary_facets}, {"euler", r.hull_euler}};
    j["volume"] = {{"tets", r.tet_volume}, {"hull", r.hull_volume}, {"relative_difference", r.volume_rel_error}};
  }
  return j;
}

}  // namespace tetstream::pipeline
