#pragma once
// What the ranks of a distributed job tell each other, as JSON: the sorted points as
// rank 0 made them (the others map the same file), and each rank's summary and
// counters for rank 0's.
#include "pipeline/run/run.hpp"
#include "pipeline/run/stage_write.hpp"
#include "pipeline/sort/point_sort.hpp"

#include <nlohmann/json.hpp>

namespace tetstream::pipeline {

nlohmann::json sorted_json(const SortedPoints& s);
SortedPoints sorted_from_json(const nlohmann::json& j);

nlohmann::json rank_json(const RunSummary::Rank& r, const WrittenWork& work);
RunSummary::Rank rank_from(const nlohmann::json& j);

}  // namespace tetstream::pipeline
