#pragma once
// `tetstream info` takes point files and .tets containers; cmd_info.cpp dispatches
// on the extension and hands containers to this function (tools/cmd_info_tets.cpp).
#include "tools/command.hpp"

#include <string>

namespace tetstream::cli {
// check: also read every point and frame and check their CRCs (and the frames'
// decoding): InputError naming the first damaged byte.
void info_tets(const std::string& path, Context& ctx, bool check = false);
}  // namespace tetstream::cli
