#include "specula/render/emitters.h"

#include "specula/render/scene_layer.h"

#include <cmath>

namespace specula {

void EmitterTable::build(const SceneTables& tables) {
  triangles_.clear();
  first_.assign(tables.instances.size(), kNone);
  total_power_ = 0.0;
  features_ = SceneFeatures{};
  features_.punctual_lights = !tables.lights.empty();
  std::vector<double> power;
  for (std::uint32_t i = 0; i < tables.instances.size(); ++i) {
    if (!tables.live(i)) continue;
    const gpu::GpuInstance& inst = tables.instances[i];
    const gpu::GpuMaterial& m = tables.materials[inst.material];
    features_.mirrors |= m.reflectivity > 0.0f;
    features_.dielectrics |= m.transmission > 0.0f;
    const double mean = (double(m.emission.x) + m.emission.y + m.emission.z) / 3.0;
    if (!(mean > 0.0)) continue;
    const gpu::GpuMesh& mesh = tables.meshes[inst.mesh];
    const bool identity = (inst.flags & gpu::kInstanceIdentity) != 0;
    const vec3* p = tables.positions.data() + mesh.first_vertex;
    const std::uint32_t first = std::uint32_t(triangles_.size());
    bool any = false;
    for (std::uint32_t t = 0; t < mesh.triangle_count; ++t) {
      const uvec3 tri = tables.triangles[mesh.first_triangle + t];
      const auto place = [&](const vec3& q) {
        return identity ? q : vec3(inst.world_from_object * vec4(q, 1.0f));
      };
      EmitterTriangle e;
      e.p0 = place(p[tri.x]);
      e.e1 = place(p[tri.y]) - e.p0;
      e.e2 = place(p[tri.z]) - e.p0;
      const dvec3 c = glm::cross(dvec3(e.e1), dvec3(e.e2));
      const double twice_area = glm::length(c);
      e.instance = i;
      e.primitive = t;
      e.emission = m.emission;
      if (twice_area > 0.0 && std::isfinite(twice_area)) {
        e.area = float(0.5 * twice_area);
        e.normal = vec3(c / twice_area);
        any = true;
      }
      // Degenerate triangles stay in place (find() indexes by primitive) with power 0.
      power.push_back(e.area > 0.0f ? mean * 0.5 * twice_area : 0.0);
      triangles_.push_back(e);
    }
    if (any) {
      first_[i] = first;
    } else {
      triangles_.resize(first);
      power.resize(first);
    }
  }
  for (const double w : power) total_power_ += w;
  if (!(total_power_ > 0.0)) {
    triangles_.clear();
    first_.assign(tables.instances.size(), kNone);
    total_power_ = 0.0;
    return;
  }
  double running = 0.0;
  for (std::size_t k = 0; k < triangles_.size(); ++k) {
    triangles_[k].pick = float(power[k] / total_power_);
    running += power[k];
    triangles_[k].cdf = float(running / total_power_);
  }
  // The last interval ends at exactly 1 whatever the rounding.
  for (std::size_t k = triangles_.size(); k-- > 0;) {
    if (triangles_[k].pick > 0.0f) {
      triangles_[k].cdf = 1.0f;
      break;
    }
  }
  features_.area_lights = true;
}

} // namespace specula
