#include "specula/core/error.h"

#include <gtest/gtest.h>

#include <string>

namespace specula {
namespace {

bool has_raw_control_byte(const std::string& s) {
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u >= 0x7f) return true;
  }
  return false;
}

TEST(Error, PrintableEscapesControlAndNonAsciiBytes) {
  const std::string raw = std::string("a\0b\nc\td\x7f\xff", 9);
  const std::string out = printable(raw);
  EXPECT_EQ(out, "a\\0b\\nc\\td\\x7f\\xff");
  EXPECT_FALSE(has_raw_control_byte(out));
}

TEST(Error, PrintableCutsLongInputAndNamesItsLength) {
  const std::string huge(1 << 20, 'A');
  const std::string out = printable(huge, 32);
  EXPECT_LT(out.size(), 64U);
  EXPECT_NE(out.find("[1048576 bytes]"), std::string::npos) << out;
  EXPECT_EQ(out.substr(0, 32), std::string(32, 'A'));
}

TEST(Error, OneLineFoldsLineBreaks) {
  EXPECT_EQ(one_line("first\nsecond\r\nthird\n"), "first; second; third");
  EXPECT_EQ(one_line("\n\nonly\n"), "only");
}

TEST(Error, ConstructorsSanitiseEveryPart) {
  const std::string huge(1 << 20, 'x');
  const Error a(std::string("fi\nle"), std::string("fi\0eld", 6), "bad value '" + huge + "'\nmore");
  const std::string what = a.what();
  EXPECT_FALSE(has_raw_control_byte(what)) << what.substr(0, 200);
  EXPECT_LT(what.size(), 2000U);
  EXPECT_EQ(what.rfind("fi\\nle: fi\\0eld: bad value 'xxx", 0), 0U) << what.substr(0, 80);
  const Error b("one\ntwo");
  EXPECT_STREQ(b.what(), "one; two");
  const Error c("f.json", 3, "x\x01y");
  EXPECT_STREQ(c.what(), "f.json:3: x\\x01y");
}

} // namespace
} // namespace specula
