#pragma once
/// \file
/// The SPIR-V of every shader in shaders/, compiled at build time (cmake/SpeculaShaders.cmake).

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

namespace specula::gpu {

/// The SPIR-V words of shader `name` (a kernel: its file name in shaders/ without .comp; a vertex
/// or fragment shader: <name>_vert / <name>_frag); throws
/// specula::Error for a name no build has.
[[nodiscard]] std::span<const std::uint32_t> shader_spirv(std::string_view name);

/// The names of every shader in this build.
[[nodiscard]] std::vector<std::string_view> shader_names();

} // namespace specula::gpu
