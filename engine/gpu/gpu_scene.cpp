#include "specula/gpu/gpu_scene.h"

#include "specula/render/scene_layer.h"

namespace specula::gpu {

GpuScene::GpuScene(Context& context, GpuStructure structure)
    : context_(context), structure_(structure) {
  for (std::uint32_t i = 0; i < kSceneBindings; ++i) {
    buffers_[i] = context.make_buffer(16);
    bindings_[i] = &buffers_[i];
  }
}

namespace {
template <class T> Buffer upload_all(Context& ctx, const std::vector<T>& data) {
  Buffer b = ctx.make_buffer(data.size() * sizeof(T));
  b.upload(std::span<const T>(data));
  return b;
}
} // namespace

const TracerUpdateStats& GpuScene::update(const SceneLayer& layer) {
  last_ = {};
  const SceneTables& t = layer.tables();
  if (!layer.delta().empty() || !buffers_[3].valid() || buffers_[3].size() <= 16) {
    buffers_[0] = upload_all(context_, t.positions);
    buffers_[1] = upload_all(context_, t.triangles);
    buffers_[2] = upload_all(context_, t.meshes);
    buffers_[3] = upload_all(context_, t.instances);
    const std::uint32_t count = std::uint32_t(t.instances.size());
    buffers_[4] = context_.make_buffer(16);
    buffers_[4].upload(&count, sizeof count);
    last_.static_builds = 1;
    last_.top_committed = true;
  }
  return last_;
}

} // namespace specula::gpu
