#pragma once
/// \file
/// Component fields by path, for the inspector, `set` in scripts and the property tests:
/// "Component.field[.x|y|z|w]" over an EntitySnapshot. Vectors take .x .y .z (colours also
/// .r .g .b), rotations .w .x .y .z (the quaternion is normalised after a write). Enums take
/// their names (Kinematics.type static|hierarchical|free, Light.type point|directional|spot).
/// RayCacheCube.enabled (0/1) adds or removes the component.

#include "editor/core/editor_session.h"

#include <string>
#include <string_view>
#include <vector>

namespace specula::editor {

/// Every editable path (scalar leaves), in inspector order.
[[nodiscard]] const std::vector<std::string>& field_paths();

/// Writes `value` (text) into the snapshot's field. Throws specula::Error (context "set PATH")
/// for an unknown path, a component the entity lacks, text that is not a number of the field's
/// kind, or a value outside what the scene loaders accept (non-finite, weights outside [0, 1],
/// ior < 1, a resolution that is not a power of two up to 4096, coordinates past kMaxCoordinate).
void set_field(EntitySnapshot& s, std::string_view path, std::string_view value);

/// The field's value as text (numbers in shortest round-trip form); empty when the entity lacks
/// the component. Throws specula::Error for an unknown path.
[[nodiscard]] std::string get_field(const EntitySnapshot& s, std::string_view path);

} // namespace specula::editor
