#pragma once
// A scratch directory for one test, removed after it: /tmp/tetstream-NAME-PID-TEST.
// Tests that write files work only in here, never next to the user's files.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include <unistd.h>

namespace tetstream::testing_util {

class ScratchDirTest : public ::testing::Test {
 protected:
  explicit ScratchDirTest(std::string name) : name_(std::move(name)) {}
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("tetstream-" + name_ + "-" + std::to_string(::getpid()) + "-" +
                                                     ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string path(const std::string& file) const { return (dir_ / file).string(); }

  std::filesystem::path dir_;

 private:
  std::string name_;
};

}  // namespace tetstream::testing_util
