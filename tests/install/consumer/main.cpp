// Uses only installed headers, all under <specula/...>: builds a world in code and ticks the
// schedule, then loads a scene file, renders it through the schedule and reads the image.
#include <specula/render/render_job.h>
#include <specula/scene/components.h>
#include <specula/scene/scene.h>
#include <specula/systems/schedule.h>

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: consumer SCENE\n");
    return 2;
  }
  try {
    specula::ecs::Registry registry;
    const auto parent = registry.create();
    const auto child = registry.create();
    specula::Transform t;
    t.translation = specula::vec3(1, 2, 3);
    registry.emplace<specula::Transform>(parent, t);
    registry.emplace<specula::Transform>(child, t);
    registry.emplace<specula::Parent>(child, specula::Parent{parent});
    specula::Schedule schedule;
    schedule.tick(registry, 1.0 / 60.0);
    const float x = registry.get<specula::WorldTransform>(child).world_from_object[3].x;
    std::printf("child world x = %g\n", double(x));
    if (x != 2.0f) return 1;

    specula::Scene scene = specula::load_scene(argv[1]);
    specula::RenderJob job;
    job.settings.mode = specula::TraceMode::Whitted;
    job.image = specula::Framebuffer(32, 24);
    specula::prepare_rendering(scene.registry, std::move(job));
    specula::Schedule frames;
    frames.tick(scene.registry, 1.0 / 60.0);
    const specula::RenderJob& done = scene.registry.resource<specula::RenderJob>();
    int lit = 0;
    for (const specula::vec3& p : done.image.pixels()) lit += (p.x + p.y + p.z) > 0.0f ? 1 : 0;
    std::printf("%s: %dx%d on %s, %d of %zu pixels lit, %llu rays\n", argv[1], done.image.width(),
                done.image.height(), done.backend.c_str(), lit, done.image.pixel_count(),
                static_cast<unsigned long long>(done.last.rays.total()));
    return lit > int(done.image.pixel_count()) / 4 ? 0 : 1; // the box fills most of the frame
  } catch (const std::exception& e) {
    std::fprintf(stderr, "consumer: %s\n", e.what());
    return 1;
  }
}
