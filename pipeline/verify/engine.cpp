// verify(): the engine's members, by concern, in one translation unit (both label
// widths are instantiated here), and the entry points.
#include "pipeline/verify/engine.hpp"

namespace tetstream::pipeline {
namespace verify_engine {

#include "pipeline/verify/engine_run.ipp"
#include "pipeline/verify/frames.ipp"
#include "pipeline/verify/pairing.ipp"
#include "pipeline/verify/hull.ipp"
#include "pipeline/verify/ranks.ipp"

}  // namespace verify_engine

using verify_engine::Engine;

VerifyReport verify(const VerifySource& source, const VerifyOptions& options, Communicator& comm) {
  options.validate();
  VerifyReport report;
  if (source.point_count() <= 0xFFFFFFFFull && !options.wide_labels) {
    Engine<std::uint32_t> e(source, options, report, comm);
    e.run();
  } else {
    Engine<std::uint64_t> e(source, options, report, comm);
    e.run();
  }
  return report;
}

VerifyReport verify_file(const std::string& path, const VerifyOptions& options, Communicator& comm) {
  std::optional<io::TetReader> reader;
  // Every rank opens the file and checks its points (each needs them all).
  together(comm, [&] {
    options.validate();
    reader.emplace(path);
    reader->verify_points();
  });
  ContainerSource source(*reader);
  return verify(source, options, comm);
}

}  // namespace tetstream::pipeline
