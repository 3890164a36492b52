#include "front_end.h"

#include <specula/core/error.h>
#include <specula/image/image_io.h>
#include <specula/scene/scene.h>
#include <specula/systems/schedule.h>

#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string_view>

namespace specula::games {

namespace {

void write_text(const std::filesystem::path& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  f.close();
  if (!f) throw Error(path.string(), "cannot write the file");
}

bool parse_u64(std::string_view s, std::uint64_t& out) {
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && end == s.data() + s.size() && !s.empty();
}

void usage(const std::string& game) {
  std::fprintf(stderr,
               "usage: %s [--size WxH] [--backend NAME] [--mode MODE] [--record FILE]\n"
               "          [--input FILE [--frames N]] [--out PNG] [--target-fps F]\n"
               "       %s --headless --frames N --input FILE [--out PNG] [--stats JSON] "
               "[--size WxH] [--backend NAME] [--mode MODE]\n",
               game.c_str(), game.c_str());
}

} // namespace

HeadlessResult run_headless(Game& game, const std::string& game_name, const InputScript& script,
                            const HeadlessOptions& options) {
  RenderJob job = game.render_job(options.width, options.height);
  job.backend = options.backend;
  if (options.mode) job.settings.mode = *options.mode;
  prepare_rendering(game.registry(), std::move(job));
  Schedule schedule;
  HeadlessResult result;
  double total_ms = 0.0, trace_ms = 0.0;
  std::uint64_t invalidated = 0, cache_hits = 0, rays = 0, nonfinite_samples = 0;
  for (std::uint64_t frame = 0; frame < options.frames; ++frame) {
    const auto start = std::chrono::steady_clock::now();
    game.step(kFrameDt, script.at(frame));
    schedule.tick(game.registry(), kFrameDt);
    total_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const RenderJob& done = game.registry().resource<RenderJob>();
    trace_ms += done.last.trace_ms;
    invalidated += done.last.cache.invalidated;
    cache_hits += done.last.cache.hits;
    rays += done.last.rays.total();
    nonfinite_samples += done.last.rays.nonfinite;
    // The integrators write a NaN or infinite sample as 0 and count it: a frame with either is
    // not a finite frame.
    bool finite = done.last.rays.nonfinite == 0;
    for (const vec3& p : done.image.pixels()) finite = finite && is_finite(p);
    if (!finite) {
      ++result.nonfinite_frames;
      if (result.first_nonfinite_frame < 0) result.first_nonfinite_frame = std::int64_t(frame);
    }
  }
  result.frames = options.frames;
  result.mean_ms = options.frames ? total_ms / double(options.frames) : 0.0;

  const RenderJob& done = game.registry().resource<RenderJob>();
  if (options.out) write_png(done.image, *options.out);
  if (options.stats) {
    char head[1024];
    std::snprintf(
        head, sizeof head,
        "{\n  \"game\": \"%s\",\n  \"frames\": %llu,\n  \"width\": %u,\n  \"height\": %u,\n"
        "  \"backend\": \"%s\",\n  \"mode\": \"%s\",\n  \"ms_per_frame\": %.4f,\n  \"fps\": %.3f,\n"
        "  \"trace_ms_per_frame\": %.4f,\n  \"rays_per_frame\": %.1f,\n"
        "  \"nonfinite_frames\": %llu,\n  \"nonfinite_samples\": %llu,\n"
        "  \"first_nonfinite_frame\": %lld,\n  \"cache_texels_invalidated\": %llu,\n"
        "  \"cache_hits\": %llu,\n",
        game_name.c_str(), static_cast<unsigned long long>(result.frames), options.width,
        options.height, done.backend.c_str(), trace_mode_name(done.settings.mode), result.mean_ms,
        result.mean_ms > 0.0 ? 1000.0 / result.mean_ms : 0.0,
        options.frames ? trace_ms / double(options.frames) : 0.0,
        options.frames ? double(rays) / double(options.frames) : 0.0,
        static_cast<unsigned long long>(result.nonfinite_frames),
        static_cast<unsigned long long>(nonfinite_samples),
        static_cast<long long>(result.first_nonfinite_frame),
        static_cast<unsigned long long>(invalidated), static_cast<unsigned long long>(cache_hits));
    write_text(*options.stats, std::string(head) + "  \"state\": {" + game.state_json() + "}\n}\n");
  }
  return result;
}

int game_main(int argc, char** argv, const std::string& game_name,
              const std::function<std::unique_ptr<Game>()>& make_game) {
  bool headless = false;
  HeadlessOptions h;
  WindowedOptions w;
  bool frames_given = false;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string_view arg = argv[i];
      const auto value = [&]() -> std::string_view {
        if (i + 1 >= argc) throw Error(std::string(arg) + " needs a value");
        return argv[++i];
      };
      if (arg == "--headless") {
        headless = true;
      } else if (arg == "--frames") {
        const std::string_view v = value();
        if (!parse_u64(v, h.frames) || h.frames == 0 || h.frames > kMaxScriptFrames) {
          throw Error("--frames: expected 1 … " + std::to_string(kMaxScriptFrames) + ", got '" +
                      std::string(v) + "'");
        }
        frames_given = true;
      } else if (arg == "--input") {
        h.input = value();
      } else if (arg == "--out") {
        h.out = value();
      } else if (arg == "--stats") {
        h.stats = value();
      } else if (arg == "--target-fps") {
        // The window's; headless replays always render the full size.
        const std::string_view v = value();
        std::uint64_t fps = 0;
        if (!parse_u64(v, fps) || fps > 1000)
          throw Error("--target-fps: expected 0 … 1000, got '" + std::string(v) + "'");
        w.target_fps = double(fps);
      } else if (arg == "--record") {
        w.record = value();
      } else if (arg == "--backend") {
        h.backend = w.backend = value();
      } else if (arg == "--mode") {
        const std::string_view v = value();
        h.mode = w.mode = parse_trace_mode(v);
        if (!h.mode) throw Error("--mode: unknown mode '" + std::string(v) + "'");
      } else if (arg == "--size") {
        const std::string_view v = value();
        const std::size_t x = v.find('x');
        std::uint64_t width = 0, height = 0;
        if (x == std::string_view::npos || !parse_u64(v.substr(0, x), width) ||
            !parse_u64(v.substr(x + 1), height) || width == 0 || height == 0 ||
            width > kMaxImageSide || height > kMaxImageSide) {
          throw Error("--size: expected WxH, each 1 … " + std::to_string(kMaxImageSide) +
                      ", got '" + std::string(v) + "'");
        }
        h.width = w.width = std::uint32_t(width);
        h.height = w.height = std::uint32_t(height);
      } else if (arg == "--help" || arg == "-h") {
        usage(game_name);
        return 0;
      } else {
        throw Error("unknown option '" + std::string(arg) + "'");
      }
    }
    if (headless) {
      if (!frames_given || h.input.empty())
        throw Error("--headless needs --frames N and --input FILE");
      if (w.record) throw Error("--record is for the windowed mode");
      const InputScript script = load_input_script(h.input);
      std::unique_ptr<Game> game = make_game();
      const HeadlessResult r = run_headless(*game, game_name, script, h);
      std::printf("%s: %llu frames at %ux%u, %.2f ms/frame (%.1f fps), score %lld%s\n",
                  game_name.c_str(), static_cast<unsigned long long>(r.frames), h.width, h.height,
                  r.mean_ms, r.mean_ms > 0 ? 1000.0 / r.mean_ms : 0.0,
                  static_cast<long long>(game->score()), game->won() ? ", goal reached" : "");
      if (r.nonfinite_frames) {
        std::fprintf(stderr, "%s: %llu frames had non-finite pixels, the first frame %lld\n",
                     game_name.c_str(), static_cast<unsigned long long>(r.nonfinite_frames),
                     static_cast<long long>(r.first_nonfinite_frame));
        return 3;
      }
      return 0;
    }
    // Windowed: --input plays a recording instead of the keyboard, --frames closes the window,
    // --out keeps the last frame.
    if (h.stats) throw Error("--stats is for --headless");
    if (!h.input.empty()) w.input = load_input_script(h.input);
    if (frames_given) w.frames = h.frames;
    w.out = h.out;
    std::unique_ptr<Game> game = make_game();
    return run_windowed(*game, game_name, w);
  } catch (const UnavailableError& e) {
    std::fprintf(stderr, "%s: %s\n", game_name.c_str(), e.what());
    return kExitUnavailable;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", game_name.c_str(), e.what());
    usage(game_name);
    return kExitBadInput;
  }
}

#ifndef SPECULA_GAMES_WINDOW
int run_windowed(Game&, const std::string&, const WindowedOptions&) {
  throw UnavailableError("this build has no window (specula::present); run with --headless");
}
#endif

} // namespace specula::games
