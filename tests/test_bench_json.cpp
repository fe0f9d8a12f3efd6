// The benchmarks' JSON writer (bench/bench_common.hpp): a name with quotes, backslashes and a
// control character, and a NaN, still give a valid JSON file that reads back as written.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <string>

#include "bench_common.hpp"

TEST_CASE("benchmark JSON rows stay valid for any name and for NaN", "[bench][json]") {
  const std::string path = "lwsccd_test_bench_rows.json";
  const std::string odd = "scene \"quoted\" C:\\frames\\a.ply\ttab";
  lwsccd_bench::write_json_rows(path, 3, [&](std::size_t i) {
    return lwsccd_bench::Json{{"scene", odd + std::to_string(i)},
                              {"median_ms", i == 1 ? std::numeric_limits<double>::quiet_NaN() : 0.25 * double(i)},
                              {"pairs", i}};
  });
  std::ifstream in(path);
  REQUIRE(in.good());
  const nlohmann::json rows = nlohmann::json::parse(in);  // throws on invalid JSON
  REQUIRE(rows.is_array());
  REQUIRE(rows.size() == 3);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    CHECK(rows[i]["scene"].get<std::string>() == odd + std::to_string(i));
    CHECK(rows[i]["pairs"].get<std::size_t>() == i);
  }
  CHECK(rows[0]["median_ms"].get<double>() == 0.0);
  CHECK(rows[1]["median_ms"].is_null());  // JSON has no NaN
  CHECK(rows[2]["median_ms"].get<double>() == 0.5);
  std::remove(path.c_str());
}

TEST_CASE("benchmark JSON rows: nothing written without a path, an error for a path that cannot be written",
          "[bench][json]") {
  int calls = 0;
  lwsccd_bench::write_json_rows("", 2, [&](std::size_t) {
    ++calls;
    return lwsccd_bench::Json::object();
  });
  CHECK(calls == 0);
  CHECK_THROWS_WITH(lwsccd_bench::write_json_rows("no/such/folder/rows.json", 1, [](std::size_t) { return lwsccd_bench::Json::object(); }),
                    Catch::Contains("cannot write no/such/folder/rows.json"));
}
