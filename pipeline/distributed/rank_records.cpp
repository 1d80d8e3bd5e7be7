#include "pipeline/distributed/rank_records.hpp"

#include <string>
#include <vector>

namespace tetstream::pipeline {

using nlohmann::json;

json sorted_json(const SortedPoints& s) {
  return {{"path", s.path},
          {"offset", s.offset},
          {"header_memory", s.header_memory},
          {"float32", s.layout.float32},
          {"id64", s.layout.id64},
          {"count", s.count},
          {"input_count", s.input_count},
          {"duplicates", s.duplicates},
          {"axis", s.axis},
          {"bbox_min", {s.bbox_min[0], s.bbox_min[1], s.bbox_min[2]}},
          {"bbox_max", {s.bbox_max[0], s.bbox_max[1], s.bbox_max[2]}},
          {"hull_labels", s.hull_labels},
          {"crc32c", s.crc32c},
          {"runs", s.runs}};
}

SortedPoints sorted_from_json(const json& j) {
  SortedPoints s;
  s.path = j.at("path").get<std::string>();
  s.offset = j.at("offset").get<std::uint64_t>();
  s.header_memory = j.at("header_memory").get<std::uint64_t>();
  s.layout = RecordLayout{j.at("float32").get<bool>(), j.at("id64").get<bool>()};
  s.count = j.at("count").get<std::uint64_t>();
  s.input_count = j.at("input_count").get<std::uint64_t>();
  s.duplicates = j.at("duplicates").get<std::uint64_t>();
  s.axis = j.at("axis").get<int>();
  for (int k = 0; k < 3; ++k) {
    s.bbox_min[k] = j.at("bbox_min").at(std::size_t(k)).get<double>();
    s.bbox_max[k] = j.at("bbox_max").at(std::size_t(k)).get<double>();
  }
  s.hull_labels = j.at("hull_labels").get<std::vector<std::uint64_t>>();
  s.crc32c = j.at("crc32c").get<std::uint32_t>();
  s.runs = j.at("runs").get<std::size_t>();
  return s;
}

json rank_json(const RunSummary::Rank& r, const WrittenWork& work) {
  return {{"first_label", r.first_label},
          {"end_label", r.end_label},
          {"segments", r.segments},
          {"zones", r.zones},
          {"tets", r.tets},
          {"frame_bytes", r.frame_bytes},
          {"seconds_index", r.seconds_index},
          {"seconds_triangulate", r.seconds_triangulate},
          {"seconds_write", r.seconds_write},
          {"message_bytes", r.message_bytes},
          {"expected_cost_share", r.expected_cost_share},
          {"work", counters_json(work)}};
}

RunSummary::Rank rank_from(const json& j) {
  RunSummary::Rank r;
  r.first_label = j.at("first_label").get<std::uint64_t>();
  r.end_label = j.at("end_label").get<std::uint64_t>();
  r.segments = j.at("segments").get<std::uint64_t>();
  r.zones = j.at("zones").get<std::uint64_t>();
  r.tets = j.at("tets").get<std::uint64_t>();
  r.frame_bytes = j.at("frame_bytes").get<std::uint64_t>();
  r.seconds_index = j.at("seconds_index").get<double>();
  r.seconds_triangulate = j.at("seconds_triangulate").get<double>();
  r.seconds_write = j.at("seconds_write").get<double>();
  r.message_bytes = j.at("message_bytes").get<std::uint64_t>();
  r.expected_cost_share = j.value("expected_cost_share", 0.0);
  return r;
}

}  // namespace tetstream::pipeline
