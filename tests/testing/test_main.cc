// gtest main with a fixed random seed, so every run of a test sees the same numbers.
#include <cstdlib>

#include <gtest/gtest.h>

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ::testing::GTEST_FLAG(random_seed) = 20111;
  std::srand(20111);
  return RUN_ALL_TESTS();
}
