#pragma once

namespace specula {

/// How an entity may move, which decides its acceleration structure:
/// Static — never moves after load (one static structure, built once);
/// Hierarchical — rigid, moves with its parent chain (per-mesh BLAS, instance per frame);
/// Free — moves or deforms freely (BVH refit / selective rebuild).
struct Kinematics {
  enum class Type { Static, Hierarchical, Free };
  Type type = Type::Static;
  friend bool operator==(const Kinematics&, const Kinematics&) = default;
};

} // namespace specula
