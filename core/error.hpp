#pragma once
// Errors that cross stage boundaries. Expected outcomes inside the kernel are
// values (see core/delaunay.hpp); exceptions are for corrupt input, I/O failures
// and bad options, and each maps to one documented exit code of the CLI.
#include <cstdint>
#include <stdexcept>
#include <string>

namespace tetstream {

enum class ExitCode : int {
  kOk = 0,
  kBadInput = 1,       // malformed, truncated, non-finite or degenerate input
  kUsage = 2,          // bad command line or options
  kIoFailure = 3,      // I/O or resource failure (disk full, unreadable file, out of memory)
  kInterrupted = 130,  // stopped by SIGINT/SIGTERM (128 + 2, the shell's convention)
};

class Error : public std::runtime_error {
 public:
  Error(ExitCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ExitCode code() const noexcept { return code_; }

 private:
  ExitCode code_;
};

// Bad input data. The message is one line: "FILE: byte OFFSET: PROBLEM" (or "line N"
// for text formats), so a user can find the fault with a hex dump or an editor.
class InputError : public Error {
 public:
  explicit InputError(const std::string& message) : Error(ExitCode::kBadInput, message) {}
  static InputError at_byte(const std::string& file, std::uint64_t offset, const std::string& problem) {
    return InputError(file + ": byte " + std::to_string(offset) + ": " + problem);
  }
  static InputError at_line(const std::string& file, std::uint64_t line, const std::string& problem) {
    return InputError(file + ": line " + std::to_string(line) + ": " + problem);
  }
};

class UsageError : public Error {
 public:
  explicit UsageError(const std::string& message) : Error(ExitCode::kUsage, message) {}
};

class IoError : public Error {
 public:
  explicit IoError(const std::string& message) : Error(ExitCode::kIoFailure, message) {}
};

}  // namespace tetstream
