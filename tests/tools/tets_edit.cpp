// tets_edit: rewrites a .tets container with one tet edited and valid checksums, the
// damage only `verify` can catch (tests/cli/mpi_cli.sh). The frames keep their cut
// (each is written as its own batch), so the edited container is split over ranks as
// the original is. The tet edited: the first of the first frame of rank RANK of K
// (pipeline/verify/split.hpp), i.e. where a distributed verify hands records over.
//   tets_edit IN OUT flip|drop|dup K RANK
//     flip  two labels swapped (the tet turned inside out)
//     drop  the tet removed
//     dup   the tet written twice, the copy right after it
// Prints the ordinal of the tet edited.
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/verify/split.hpp"

#include <algorithm>
#include <cstdint>
#include <iostream>
#include <numeric>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  using namespace tetstream;
  if (argc != 6) {
    std::cerr << "usage: tets_edit IN OUT flip|drop|dup K RANK\n";
    return 2;
  }
  const std::string in = argv[1], out = argv[2], kind = argv[3];
  const int ranks = std::stoi(argv[4]), rank = std::stoi(argv[5]);
  try {
    io::TetReader r(in);
    const auto& frames = r.frames();
    // The visiting order of verify: frames by smallest label, stable.
    std::vector<std::size_t> order(frames.size());
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return frames[a].base_label < frames[b].base_label; });
    std::vector<std::uint64_t> mins, counts;
    for (std::size_t k : order) mins.push_back(frames[k].base_label), counts.push_back(frames[k].tet_count);
    const pipeline::VerifySplit split = pipeline::split_frames(mins, counts, ranks);
    const std::size_t at = split.first[std::size_t(rank)];
    if (at >= frames.size()) throw std::runtime_error("rank " + std::to_string(rank) + " has no frames");
    const std::size_t target_frame = order[at];
    std::cout << frames[target_frame].first_tet << "\n";

    io::TetWriterOptions wo;
    wo.sync = false;
    wo.frame_tets = 1;
    for (const auto& f : frames) wo.frame_tets = std::max(wo.frame_tets, f.tet_count + 1);
    io::TetWriter w(out, r.header(), wo);
    std::vector<double> xyz(3 * r.point_count());
    std::vector<std::uint64_t> ids(r.point_count());
    r.read_points(0, r.point_count(), xyz.data(), ids.data());
    w.add_points(xyz.data(), ids.data(), r.point_count());
    std::vector<std::uint64_t> labels;
    for (std::size_t k = 0; k < frames.size(); ++k) {
      r.read_frame(k, labels);
      if (k == target_frame) {
        if (kind == "flip")
          std::swap(labels[0], labels[1]);
        else if (kind == "drop")
          labels.erase(labels.begin(), labels.begin() + 4);
        else if (kind == "dup")
          labels.insert(labels.begin() + 4, labels.begin(), labels.begin() + 4);
        else
          throw std::runtime_error("unknown edit " + kind);
      }
      w.add_tets(std::span<const std::uint64_t>(labels));
    }
    w.finish();
  } catch (const std::exception& e) {
    std::cerr << "tets_edit: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
