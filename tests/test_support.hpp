// Shared helpers for the tests.
#pragma once

#include <cstddef>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

namespace lwsccd_test {

/// The shared data folder: $LWSCCD_DATA_DIR if set, else the path configured at build time.
inline std::string data_dir() {
  if (const char* env = std::getenv("LWSCCD_DATA_DIR")) return env;
  return LWSCCD_TEST_DATA_DIR;
}

inline bool have_data() { return std::filesystem::is_directory(data_dir() + "/scenes"); }

/// A fresh empty temporary folder for one test, removed when the object dies.
class TempDir {
 public:
  explicit TempDir(const std::string& tag) {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() / ("lwsccd-" + tag + "-" + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string path() const { return path_.string(); }

 private:
  std::filesystem::path path_;
};

/// Whether a sequence of steps restarted from the root exactly where a front growth limit says
/// (FrontPolicy): the first step, a step that rebuilt the BVH, and every step after one whose
/// front exceeded `limit` times the front recorded by the last restart.
inline bool restarts_follow_growth_limit(const std::vector<bool>& restarted, const std::vector<bool>& rebuilt,
                                         const std::vector<std::size_t>& front, double limit) {
  std::size_t at_restart = 0;
  for (std::size_t i = 0; i < restarted.size(); ++i) {
    const bool expected = i == 0 || rebuilt[i] || static_cast<double>(front[i - 1]) > limit * static_cast<double>(at_restart);
    if (restarted[i] != expected) return false;
    if (restarted[i]) at_restart = front[i];
  }
  return true;
}

}  // namespace lwsccd_test
