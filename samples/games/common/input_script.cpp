#include "input_script.h"

#include <specula/core/error.h>
#include <specula/core/file_io.h>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>

namespace specula::games {

namespace {

constexpr std::array<const char*, kKeyCount> kKeyNames = {"left", "right", "up", "down", "space"};

std::vector<std::string_view> split(std::string_view text, char separator) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = text.find(separator, start);
    const std::size_t stop = end == std::string_view::npos ? text.size() : end;
    parts.push_back(text.substr(start, stop - start));
    start = stop + 1;
  }
  return parts;
}

std::vector<std::string_view> words(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

bool parse_frame(std::string_view s, std::uint64_t& out) {
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && end == s.data() + s.size() && !s.empty();
}

bool parse_float(std::string_view s, float& out) {
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && end == s.data() + s.size() && !s.empty() && std::isfinite(out);
}

std::uint32_t parse_keys(std::string_view list, const std::string& name, int line) {
  std::uint32_t bits = 0;
  for (const std::string_view k : split(list, ',')) {
    const std::optional<Key> key = parse_key(k);
    if (!key) {
      throw Error(name, line, "unknown key '" + std::string(k) + "' (left right up down space)");
    }
    bits |= 1u << unsigned(*key);
  }
  return bits;
}

} // namespace

std::optional<Key> parse_key(std::string_view name) {
  for (int i = 0; i < kKeyCount; ++i) {
    if (name == kKeyNames[std::size_t(i)]) return Key(i);
  }
  return std::nullopt;
}

const char* key_name(Key key) { return kKeyNames[std::size_t(key)]; }

InputScript parse_input_script(std::string_view text, const std::string& name) {
  InputScript script;
  int line_number = 0;
  for (std::string_view line : split(text, '\n')) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }
    const std::vector<std::string_view> w = words(line);
    if (w.empty()) continue;

    std::uint64_t first = 0, last = 0;
    const std::size_t dash = w[0].find('-');
    const bool range_ok =
        dash == std::string_view::npos
            ? parse_frame(w[0], first) && ((last = first), true)
            : parse_frame(w[0].substr(0, dash), first) && parse_frame(w[0].substr(dash + 1), last);
    if (!range_ok) {
      throw Error(name, line_number,
                  "expected FRAME or FIRST-LAST, got '" + std::string(w[0]) + "'");
    }
    if (last < first) throw Error(name, line_number, "frame range ends before it starts");
    if (last >= kMaxScriptFrames) {
      throw Error(name, line_number,
                  "frame " + std::to_string(last) + " is beyond the limit of " +
                      std::to_string(kMaxScriptFrames));
    }
    if (first < script.frames.size()) {
      throw Error(name, line_number,
                  "frames must ascend without overlapping (frame " + std::to_string(first) +
                      " already given)");
    }

    GameInput input;
    for (std::size_t i = 1; i < w.size(); ++i) {
      const std::size_t eq = w[i].find('=');
      const std::string_view field = w[i].substr(0, eq);
      const std::string_view value = eq == std::string_view::npos ? "" : w[i].substr(eq + 1);
      if (eq == std::string_view::npos || value.empty()) {
        throw Error(name, line_number,
                    "expected down=KEYS, press=KEYS or mouse=DX,DY, got '" + std::string(w[i]) +
                        "'");
      }
      if (field == "down") {
        input.down |= parse_keys(value, name, line_number);
      } else if (field == "press") {
        input.pressed |= parse_keys(value, name, line_number);
      } else if (field == "mouse") {
        const std::vector<std::string_view> d = split(value, ',');
        if (d.size() != 2 || !parse_float(d[0], input.mouse_dx) ||
            !parse_float(d[1], input.mouse_dy)) {
          throw Error(name, line_number,
                      "mouse needs two finite numbers DX,DY, got '" + std::string(value) + "'");
        }
      } else {
        throw Error(name, line_number,
                    "unknown field '" + std::string(field) + "' (down, press, mouse)");
      }
    }
    script.frames.resize(last + 1);
    for (std::uint64_t f = first; f <= last; ++f) script.frames[f] = input;
  }
  return script;
}

InputScript load_input_script(const std::filesystem::path& path) {
  // A script of kMaxScriptFrames lines of all keys is far below this.
  return parse_input_script(read_file_bounded(path, 1ull << 30, "input file"), path.string());
}

std::string format_input_script(std::span<const GameInput> frames) {
  std::string out = "# specula game input: FRAME[-LAST] [down=KEYS] [press=KEYS] [mouse=DX,DY]\n";
  const auto keys = [](std::uint32_t bits) {
    std::string s;
    for (int k = 0; k < kKeyCount; ++k) {
      if ((bits >> unsigned(k)) & 1u)
        s += (s.empty() ? "" : ",") + std::string(kKeyNames[std::size_t(k)]);
    }
    return s;
  };
  std::size_t i = 0;
  while (i < frames.size()) {
    std::size_t j = i;
    while (j + 1 < frames.size() && frames[j + 1] == frames[i]) ++j;
    const GameInput& in = frames[i];
    if (in != GameInput{}) {
      out += std::to_string(i);
      if (j > i) out += "-" + std::to_string(j);
      if (in.down) out += " down=" + keys(in.down);
      if (in.pressed) out += " press=" + keys(in.pressed);
      if (in.mouse_dx != 0.0f || in.mouse_dy != 0.0f) {
        char buf[64];
        std::snprintf(buf, sizeof buf, " mouse=%.9g,%.9g", double(in.mouse_dx),
                      double(in.mouse_dy));
        out += buf;
      }
      out += "\n";
    }
    i = j + 1;
  }
  return out;
}

} // namespace specula::games
