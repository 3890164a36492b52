#include "bench_common.h"

#include "specula/scene/components.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/mesh_io.h"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>

#include <chrono>
#include <filesystem>
#include <memory>
#include <vector>

namespace specula::bench {

std::vector<std::string> split_list(const std::string& list) {
  std::vector<std::string> items;
  for (std::size_t begin = 0; begin <= list.size();) {
    std::size_t end = list.find(',', begin);
    if (end == std::string::npos) end = list.size();
    if (end > begin) items.push_back(list.substr(begin, end - begin));
    begin = end + 1;
  }
  return items;
}

double time_ms(const std::function<void()>& f) {
  const auto start = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

TriangleMesh subdivided(const TriangleMesh& base, int levels) {
  if (levels == 0) return base;
  using OMesh = OpenMesh::TriMesh_ArrayKernelT<>;
  OMesh om;
  std::vector<OMesh::VertexHandle> handles;
  for (const vec3& p : base.positions)
    handles.push_back(om.add_vertex(OMesh::Point(p.x, p.y, p.z)));
  for (const uvec3& t : base.triangles) om.add_face(handles[t.x], handles[t.y], handles[t.z]);
  OpenMesh::Subdivider::Uniform::LoopT<OMesh> loop;
  loop.attach(om);
  loop(static_cast<std::size_t>(levels));
  loop.detach();
  TriangleMesh out;
  for (const auto& v : om.vertices()) {
    const auto& p = om.point(v);
    out.positions.emplace_back(p[0], p[1], p[2]);
  }
  for (const auto& f : om.faces()) {
    uvec3 t;
    int k = 0;
    for (const auto& v : om.fv_range(f)) t[k++] = static_cast<std::uint32_t>(v.idx());
    out.triangles.push_back(t);
  }
  out.compute_vertex_normals();
  return out;
}

Scene mesh_scene(const TriangleMesh& mesh, std::uint32_t size) {
  Scene scene;
  scene.settings.width = scene.settings.height = size;
  ecs::Registry& reg = scene.registry;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(mesh), {}, {}, 0});
  reg.emplace<Material>(e);
  reg.emplace<Kinematics>(e);
  update_world_transforms(reg, 0);
  add_defaults(scene);
  return scene;
}

TriangleMesh load_bunny(const Options& o) {
  return load_mesh_file(std::filesystem::path(o.source_dir) / "samples/models/bunny.obj");
}

} // namespace specula::bench
