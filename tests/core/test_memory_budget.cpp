#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/core/memory_budget.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <string>

namespace specula {
namespace {

TEST(MemoryBudget, ParsesSizesWithBinaryUnits) {
  EXPECT_EQ(parse_byte_size("4096"), std::uint64_t{4096});
  EXPECT_EQ(parse_byte_size("512M"), std::uint64_t{512} << 20);
  EXPECT_EQ(parse_byte_size("1.5G"), std::uint64_t{3} << 29);
  EXPECT_EQ(parse_byte_size("2gib"), std::uint64_t{2} << 30);
  for (const char* bad : {"", "0", "-1", "abc", "1Q", "nan", "1e999T", "99999999999T"}) {
    EXPECT_FALSE(parse_byte_size(bad).has_value()) << bad;
  }
}

TEST(MemoryBudget, CheckRefusesMoreThanTheBudgetNamingFileAndOrigin) {
  const MemoryBudget budget{std::uint64_t{1} << 30, "--memory-limit 1G"};
  EXPECT_NO_THROW(check_memory(std::uint64_t{1} << 30, budget, "x.png", "decoding"));
  try {
    check_memory(std::uint64_t{3} << 30, budget, "x.png", "decoding this PNG");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("x.png: decoding this PNG needs about 3", 0), 0U) << what;
    EXPECT_NE(what.find("--memory-limit 1G"), std::string::npos) << what;
  }
}

TEST(MemoryBudget, DefaultIsWithinPhysicalMemory) {
  const MemoryBudget budget = memory_budget({}, "--memory-limit");
  EXPECT_GE(budget.bytes, std::uint64_t{256} << 20);
  EXPECT_LE(budget.bytes, std::max(physical_memory_bytes(), std::uint64_t{256} << 20));
  EXPECT_THROW((void)memory_budget("lots", "--memory-limit"), Error);
  EXPECT_EQ(memory_budget("2G", "--memory-limit").bytes, std::uint64_t{2} << 30);
}

} // namespace
} // namespace specula
