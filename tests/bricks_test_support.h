#pragma once
// Shared by the multi-brick tests (test_bricks.cpp, test_bricks_ooc.cpp): a small, fast brick config.
#include <string>
#include "test_support.h"
#include "vnr/bricks.h"

namespace vnr::test {

inline TrainingSetup small_brick_setup(const std::string& volume, uint32_t seed = 5) {
  TrainingSetup s;
  s.volume = volume;
  s.config_json = small_hash_config(10, 16, 1);
  s.batch = 4096;
  s.seed = seed;
  s.device = "cpu";
  s.macrocell_size = 8;
  return s;
}

inline BricksRunOptions brick_steps(int64_t n) {
  BricksRunOptions o;
  o.brick.steps = n;
  return o;
}

}  // namespace vnr::test
