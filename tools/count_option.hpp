#pragma once
// Counts written as people write them: "1000000", "1e6", "2.5e6", "1E+06". A transform
// for CLI11 options of integer type: a number in scientific or decimal notation that is
// a whole number in range becomes its digits; anything else is left for CLI11's own
// conversion to refuse ("Could not convert"), or refused here when it is not whole.
#include <CLI/CLI.hpp>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

namespace tetstream::cli {

inline CLI::Validator scientific_count() {
  return CLI::Validator(
      [](std::string& value) -> std::string {
        const std::string refused = value + " is not a whole number of points from 0 to 2^64-1";
        if (value.find_first_of("eE.") == std::string::npos) {
          // Digits only: strtoull would take "-1" as 2^64-1 and CLI11 wraps past 2^64.
          if (value.empty() || value.find_first_not_of("0123456789") != std::string::npos) return refused;
          errno = 0;
          (void)std::strtoull(value.c_str(), nullptr, 10);
          return errno == ERANGE ? refused : "";
        }
        const char* begin = value.c_str();
        char* end = nullptr;
        errno = 0;
        const double v = std::strtod(begin, &end);
        if (end == begin || *end != '\0' || errno == ERANGE) return "";  // CLI11 says why
        // 2^64 is exactly representable; every double below it is a whole uint64 or not.
        if (!(v >= 0) || v >= 18446744073709551616.0 || v != std::floor(v)) {
          return refused;
        }
        value = std::to_string(static_cast<std::uint64_t>(v));
        return "";
      },
      "", "count");
}

}  // namespace tetstream::cli
