#include "core/io/text_tokens.h"

#include <cmath>
#include <string>
#include <vector>

#include "gtest/gtest.h"

namespace rpsr::core::io_internal {
namespace {

TEST(TextTokensTest, ParsesDoublesStrictly) {
  double value = 0.0;
  EXPECT_TRUE(ParseDoubleToken("1.5", &value));
  EXPECT_EQ(value, 1.5);
  EXPECT_TRUE(ParseDoubleToken("+2e3", &value));
  EXPECT_EQ(value, 2000.0);
  EXPECT_TRUE(ParseDoubleToken("-.25", &value));
  EXPECT_EQ(value, -0.25);
  EXPECT_TRUE(ParseDoubleToken("nan", &value));
  EXPECT_TRUE(std::isnan(value));
  for (const char* bad : {"", "+", "1.5x", "abc", "1e999", "0x10", "--1", "+-1", "1 "}) {
    EXPECT_FALSE(ParseDoubleToken(bad, &value)) << bad;
  }
}

TEST(TextTokensTest, ParsesIntegersStrictly) {
  int64_t signed_value = 0;
  uint64_t unsigned_value = 0;
  EXPECT_TRUE(ParseInt64Token("-42", &signed_value));
  EXPECT_EQ(signed_value, -42);
  EXPECT_TRUE(ParseUint64Token("+7", &unsigned_value));
  EXPECT_EQ(unsigned_value, 7u);
  EXPECT_FALSE(ParseUint64Token("-1", &unsigned_value));
  EXPECT_FALSE(ParseInt64Token("99999999999999999999", &signed_value));
  EXPECT_FALSE(ParseInt64Token("1.0", &signed_value));
}

TEST(TextTokensTest, ShortestDecimalsReadBackExactly) {
  for (const float value : {0.1f, -3.4028235e38f, 1e-45f, 123456.789f}) {
    std::string text;
    AppendShortestDecimal(value, &text);
    double parsed = 0.0;
    ASSERT_TRUE(ParseDoubleToken(text, &parsed)) << text;
    EXPECT_EQ(static_cast<float>(parsed), value) << text;
  }
}

TEST(TextTokensTest, ScannersTrackLines) {
  LineScanner lines("a\r\nb\n\nc");
  absl::string_view line;
  std::vector<std::string> seen;
  while (lines.Next(&line)) seen.emplace_back(line);
  EXPECT_EQ(seen, (std::vector<std::string>{"a", "b", "", "c"}));
  EXPECT_EQ(lines.line_number(), 4u);

  TokenScanner tokens(" x\n\n y  z\n", 10);
  absl::string_view token;
  ASSERT_TRUE(tokens.Next(&token));
  EXPECT_EQ(token, "x");
  EXPECT_EQ(tokens.line_number(), 10u);
  ASSERT_TRUE(tokens.Next(&token));
  EXPECT_EQ(token, "y");
  EXPECT_EQ(tokens.line_number(), 12u);
  ASSERT_TRUE(tokens.Next(&token));
  EXPECT_FALSE(tokens.Next(&token));
}

TEST(TextTokensTest, SplitsOnDelimiterKeepingEmptyColumns) {
  std::vector<absl::string_view> columns;
  SplitOnDelimiter(" 1 , 2,,3 ", ',', &columns);
  ASSERT_EQ(columns.size(), 4u);
  EXPECT_EQ(columns[0], "1");
  EXPECT_EQ(columns[2], "");
  EXPECT_EQ(columns[3], "3");
}

}  // namespace
}  // namespace rpsr::core::io_internal
