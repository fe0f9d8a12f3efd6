// Runner for the tests on ../shared/data: reports "Skipped" (exit 77) with a message when absent.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include <cstdio>

#include "test_support.hpp"

int main(int argc, char* argv[]) {
  if (!lwsccd_test::have_data()) {
    std::printf("SKIPPED: shared data not found at '%s' (set LWSCCD_DATA_DIR or configure with "
                "-DLWSCCD_DATA_DIR=...)\n", lwsccd_test::data_dir().c_str());
    return LWSCCD_SKIP_CODE;
  }
  std::printf("using shared data at %s\n", lwsccd_test::data_dir().c_str());
  return Catch::Session().run(argc, argv);
}
