#include "scene_kit.h"

#include <specula/geometry/primitives.h>

#include <memory>

namespace specula::games {

MeshSource primitive(const std::string& name, float radius, vec3 size, float height) {
  MeshSource s;
  s.kind = MeshSource::Kind::Primitive;
  s.primitive = name;
  s.radius = radius;
  s.size = size;
  s.height = height;
  s.segments = 24;
  s.rings = name == "plane" ? 1 : 12;
  return s;
}

Transform at(const dvec3& translation, const quat& rotation, const vec3& scale) {
  Transform t;
  t.translation = translation;
  t.rotation = rotation;
  t.scale = scale;
  return t;
}

ecs::Entity add_node(ecs::Registry& reg, const Transform& t, Kinematics::Type kinematics,
                     ecs::Entity parent) {
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, t);
  reg.emplace<Kinematics>(e, Kinematics{kinematics});
  if (parent != ecs::null_entity) reg.emplace<Parent>(e, Parent{parent});
  return e;
}

ecs::Entity add_mesh(ecs::Registry& reg, const MeshSource& source, const Transform& t,
                     const Material& m, Kinematics::Type kinematics, ecs::Entity parent) {
  const ecs::Entity e = add_node(reg, t, kinematics, parent);
  Mesh mesh;
  mesh.geometry = std::make_shared<const TriangleMesh>(make_primitive(source, "game scene"));
  mesh.source = source;
  reg.emplace<Mesh>(e, std::move(mesh));
  reg.emplace<Material>(e, m);
  return e;
}

dmat4 world_of(ecs::Registry& reg, ecs::Entity e) {
  dmat4 m = reg.get<Transform>(e).parent_from_local();
  for (const Parent* p = reg.try_get<Parent>(e); p; p = reg.try_get<Parent>(p->entity)) {
    m = reg.get<Transform>(p->entity).parent_from_local() * m;
  }
  return m;
}

dvec3 closest_on_box(const dmat4& world_from_object, const Aabb& local, const dvec3& p,
                     bool& inside) {
  const dvec3 q = dvec3(glm::inverse(world_from_object) * dvec4(p, 1.0));
  const dvec3 lo(local.min), hi(local.max);
  dvec3 c = glm::clamp(q, lo, hi);
  inside = c == q;
  if (inside) {
    // Out through the nearest face, measured in world units (the axes may be scaled).
    double best = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      const double axis_scale = glm::length(dvec3(world_from_object[a]));
      for (const double face : {lo[a], hi[a]}) {
        const double d = std::abs(q[a] - face) * axis_scale;
        if (d < best) {
          best = d;
          c = q;
          c[a] = face;
        }
      }
    }
  }
  return dvec3(world_from_object * dvec4(c, 1.0));
}

} // namespace specula::games
