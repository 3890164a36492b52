#include "specula/core/error.h"

#include <algorithm>
#include <utility>

namespace specula {

namespace {

constexpr std::size_t kFileBytes = 256;
constexpr std::size_t kFieldBytes = 128;
constexpr std::size_t kMessageBytes = 1024;

void append_escaped(std::string& out, unsigned char c) {
  static constexpr char kHex[] = "0123456789abcdef";
  switch (c) {
  case '\n': out += "\\n"; return;
  case '\r': out += "\\r"; return;
  case '\t': out += "\\t"; return;
  case '\0': out += "\\0"; return;
  default: break;
  }
  if (c < 0x20 || c >= 0x7f) {
    out += "\\x";
    out += kHex[c >> 4];
    out += kHex[c & 15];
  } else {
    out += char(c);
  }
}

std::string cut(std::string_view text, std::size_t max_bytes, bool fold_lines) {
  std::string out;
  out.reserve(std::min(text.size(), max_bytes) + 24);
  std::size_t used = 0;
  for (; used < text.size() && out.size() < max_bytes; ++used) {
    const auto c = static_cast<unsigned char>(text[used]);
    if (fold_lines && (c == '\n' || c == '\r')) {
      // "a\r\nb" and "a\n\nb" fold to one separator; a trailing break is dropped.
      while (used + 1 < text.size() && (text[used + 1] == '\n' || text[used + 1] == '\r')) ++used;
      if (used + 1 < text.size() && !out.empty()) out += "; ";
      continue;
    }
    append_escaped(out, c);
  }
  if (used < text.size()) out += "...[" + std::to_string(text.size()) + " bytes]";
  return out;
}

} // namespace

std::string printable(std::string_view text, std::size_t max_bytes) { return cut(text, max_bytes, false); }

std::string one_line(std::string_view text, std::size_t max_bytes) { return cut(text, max_bytes, true); }

Error::Error(const std::string& message)
    : std::runtime_error(one_line(message, kMessageBytes)), message_(one_line(message, kMessageBytes)) {}

Error::Error(std::string file, const std::string& message)
    : std::runtime_error(printable(file, kFileBytes) + ": " + one_line(message, kMessageBytes)),
      file_(std::move(file)), message_(one_line(message, kMessageBytes)) {}

Error::Error(std::string file, int line, const std::string& message)
    : std::runtime_error(printable(file, kFileBytes) + ":" + std::to_string(line) + ": " +
                         one_line(message, kMessageBytes)),
      file_(std::move(file)), message_(one_line(message, kMessageBytes)), line_(line) {}

Error::Error(std::string file, std::string field, const std::string& message)
    : std::runtime_error(printable(file, kFileBytes) + ": " + printable(field, kFieldBytes) + ": " +
                         one_line(message, kMessageBytes)),
      file_(std::move(file)), field_(std::move(field)), message_(one_line(message, kMessageBytes)) {}

} // namespace specula
