#pragma once
/// \file
/// The SPIR-V of every kernel in shaders/, compiled at build time (cmake/SpeculaShaders.cmake).

#include <cstdint>
#include <span>
#include <string_view>

namespace specula::gpu {

/// The SPIR-V words of kernel `name` (the file name in shaders/ without .comp); throws
/// specula::Error for a name no build has.
[[nodiscard]] std::span<const std::uint32_t> shader_spirv(std::string_view name);

} // namespace specula::gpu
