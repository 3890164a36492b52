#pragma once
/// \file
/// Reader for BART's Animated File Format (Lext, Assarsson, Möller, "A benchmark for animated ray
/// tracing", IEEE CG&A 2001): Eric Haines' NFF 3.9 plus materials with colours (`fm`), meshes,
/// animated triangles, named static and keyframed transforms, keyframes with Kochanek–Bartels
/// splines, includes and animation parameters. What maps onto which component, and what is not
/// supported, is in docs/scene-format.md ("BART / AFF").

#include "specula/scene/scene.h"

#include <filesystem>

namespace specula {

/// Most nested includes (`i`) one file may pull in: deeper is an error, as is a cycle.
inline constexpr int kMaxAffIncludeDepth = 16;

/// Reads an .aff (or plain .nff) file and the files it includes into a Scene: every `x NAME` and
/// `xs` an entity with Name, Transform and (keyframed) Animation, parented as nested; geometry
/// below a transform merged into one Mesh entity per primitive kind and material, parented to
/// it; `tpa` triangles into vertex-animated meshes; `v` the Camera and RenderSettings; `k camera`
/// a CameraPath. Throws specula::Error naming the file and line and the problem.
[[nodiscard]] Scene load_aff_scene(const std::filesystem::path& path);

} // namespace specula
