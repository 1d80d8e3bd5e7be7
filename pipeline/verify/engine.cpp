// verify(): the engine's members, by concern, in one translation unit (both label
// widths are instantiated here), and the entry points.
#include "pipeline/verify/engine.hpp"

namespace tetstream::pipeline {
namespace verify_engine {

#include "pipeline/verify/engine_run.ipp"
#include "pipeline/verify/frames.ipp"
#include "pipeline/verify/pairing.ipp"
#include "pipeline/verify/hull.ipp"

}  // namespace verify_engine

using verify_engine::Engine;

VerifyReport verify(const VerifySource& source, const VerifyOptions& options) {
  options.validate();
  VerifyReport report;
  if (source.point_count() <= 0xFFFFFFFFull && !options.wide_labels) {
    Engine<std::uint32_t> e(source, options, report);
    e.run();
  } else {
    Engine<std::uint64_t> e(source, options, report);
    e.run();
  }
  return report;
}

VerifyReport verify_file(const std::string& path, const VerifyOptions& options) {
  options.validate();
  io::TetReader reader(path);
  reader.verify_points();
  ContainerSource source(reader);
  return verify(source, options);
}

}  // namespace tetstream::pipeline
