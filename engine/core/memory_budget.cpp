#include "specula/core/memory_budget.h"

#include "specula/core/error.h"
#include "specula/core/file_io.h"

#include <sys/resource.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>

namespace specula {

std::uint64_t default_memory_budget() {
  constexpr std::uint64_t kFloor = std::uint64_t{256} << 20;
  const std::uint64_t physical = physical_memory_bytes();
  std::uint64_t budget = physical > 0 ? physical / 4 * 3 : kFloor;
  for (const int resource : {RLIMIT_AS, RLIMIT_DATA}) {
    rlimit limit{};
    if (getrlimit(resource, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
      budget = std::min<std::uint64_t>(budget, limit.rlim_cur);
  }
  return std::max(budget, kFloor);
}

std::optional<std::uint64_t> parse_byte_size(std::string_view text) {
  double value = 0.0;
  const auto [end, ec] =
      std::from_chars(text.data(), text.data() + text.size(), value, std::chars_format::fixed);
  if (ec != std::errc{} || end == text.data()) return std::nullopt;
  std::string unit(end, text.data() + text.size());
  if (!unit.empty() && unit.front() == ' ') unit.erase(0, 1);
  std::transform(unit.begin(), unit.end(), unit.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  int shift = 0;
  if (!unit.empty() && unit != "b" && unit != "bytes") {
    const char* const units = "kmgt";
    const char* const found = std::char_traits<char>::find(units, 4, unit[0]);
    if (found == nullptr) return std::nullopt;
    const std::string_view rest = std::string_view(unit).substr(1);
    if (!rest.empty() && rest != "b" && rest != "ib") return std::nullopt;
    shift = 10 * int(found - units + 1);
  }
  const double bytes = std::ldexp(value, shift);
  if (!(bytes >= 1.0 && bytes < 0x1p63)) return std::nullopt; // also NaN
  return static_cast<std::uint64_t>(bytes);
}

std::string byte_size_text(std::uint64_t bytes) {
  if (bytes < 1024) return std::to_string(bytes) + " bytes";
  const char* const units[] = {"KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double value = double(bytes) / 1024.0;
  int unit = 0;
  while (value >= 1024.0 && unit < 5) {
    value /= 1024.0;
    ++unit;
  }
  char text[32];
  std::snprintf(text, sizeof text,
                value < 10.0    ? "%.2f %s"
                : value < 100.0 ? "%.1f %s"
                                : "%.0f %s",
                value, units[unit]);
  return text;
}

MemoryBudget memory_budget(std::string_view option, std::string_view option_name) {
  if (option.empty())
    return {default_memory_budget(),
            "the default: 3/4 of physical memory, within ulimit -v; --memory-limit sets another"};
  const std::optional<std::uint64_t> bytes = parse_byte_size(option);
  if (!bytes) {
    throw Error(std::string(option_name),
                "expected a size such as 512M or 4G, got '" + printable(option) + "'");
  }
  return {*bytes, std::string(option_name) + " " + printable(option)};
}

void check_memory(std::uint64_t needed, const MemoryBudget& budget, const std::string& file,
                  const std::string& what) {
  if (needed <= budget.bytes) return;
  throw Error(file, what + " needs about " + byte_size_text(needed) +
                        ", more than the memory budget of " + byte_size_text(budget.bytes) + " (" +
                        budget.origin + ")");
}

} // namespace specula
