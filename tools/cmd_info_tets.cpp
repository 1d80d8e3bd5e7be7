// Placeholder until the container work lands (a colleague overwrites this file).
#include "core/error.hpp"
#include "tools/info_tets.hpp"

namespace tetstream::cli {
void info_tets(const std::string& path, Context&) {
  throw UsageError("container support not built yet: cannot show " + path);
}
}  // namespace tetstream::cli
