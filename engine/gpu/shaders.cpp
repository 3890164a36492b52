#include "specula/gpu/shaders.h"

#include "specula/core/error.h"

#include <string>

#include "specula/spv/shader_table.inc"

namespace specula::gpu {

namespace {
struct Entry {
  std::string_view name;
  const std::uint32_t* words;
  std::size_t count;
};
const Entry kShaders[] = {SPECULA_SHADER_ENTRIES};
} // namespace

std::span<const std::uint32_t> shader_spirv(std::string_view name) {
  for (const Entry& e : kShaders)
    if (e.name == name) return {e.words, e.count};
  throw Error("shaders", "no kernel named '" + std::string(name) + "' in this build");
}

std::vector<std::string_view> shader_names() {
  std::vector<std::string_view> names;
  for (const Entry& e : kShaders) names.push_back(e.name);
  return names;
}

} // namespace specula::gpu
