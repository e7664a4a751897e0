#include "vnr/core/rng.h"
#include <random>

namespace vnr {
uint32_t seed_seq_first_word(uint32_t seed) {
  std::seed_seq seq{seed};
  uint32_t words[2];
  seq.generate(words, words + 2);
  return words[0];
}
}  // namespace vnr
