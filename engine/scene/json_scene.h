#pragma once
/// \file
/// Specula's JSON scene format (docs/scene-format.md, schema docs/scene.schema.json).

#include "specula/scene/scene.h"

#include <filesystem>
#include <string>

namespace specula {

/// Reads a JSON scene. Mesh files are resolved relative to the scene file. Throws specula::Error
/// naming the file and the JSON path of the bad field (e.g. "entities[3].transform.scale").
/// The format's reader only: Kinematics are those the file states, and the parent links are
/// checked for the format (names exist, are unique) but not for cycles; load_scene does the
/// checks and inference common to every format.
[[nodiscard]] Scene load_json_scene(const std::filesystem::path& path);

/// Parses JSON text; `name` is used in messages, `base_dir` resolves mesh files.
[[nodiscard]] Scene parse_json_scene(const std::string& text, const std::string& name,
                                     const std::filesystem::path& base_dir);

/// Writes the scene as JSON text. Round trip is lossless for everything the format holds;
/// entities carrying DefaultTag are left out. Mesh file paths are written as stored
/// (relative to the scene file they came from).
[[nodiscard]] std::string write_json_scene(Scene& scene);

/// write_json_scene to a file; throws specula::Error when it cannot be written.
void save_json_scene(Scene& scene, const std::filesystem::path& path);

} // namespace specula
