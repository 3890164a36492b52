#include "editor/core/script.h"

#include "editor/core/fields.h"
#include "editor/core/navigation.h"
#include "specula/core/error.h"
#include "specula/core/file_io.h"

#include <charconv>
#include <cmath>
#include <sstream>
#include <vector>

namespace specula::editor {

namespace {

constexpr std::uint64_t kMaxScriptBytes = std::uint64_t(16) << 20;

/// Whitespace-separated words; "double quoted" words may hold spaces.
std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> words;
  std::size_t i = 0;
  while (i < line.size()) {
    if (std::isspace(static_cast<unsigned char>(line[i]))) {
      ++i;
      continue;
    }
    if (line[i] == '#') break;
    std::string w;
    if (line[i] == '"') {
      const std::size_t end = line.find('"', i + 1);
      if (end == std::string::npos) throw std::invalid_argument("unterminated quote");
      w = line.substr(i + 1, end - i - 1);
      i = end + 1;
    } else {
      while (i < line.size() && !std::isspace(static_cast<unsigned char>(line[i]))) w += line[i++];
    }
    words.push_back(std::move(w));
  }
  return words;
}

double number(const std::string& text) {
  double v = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc{} || end != text.data() + text.size() || !std::isfinite(v))
    throw std::invalid_argument("expected a number, got '" + text + "'");
  return v;
}

std::uint32_t count(const std::string& text) {
  const double v = number(text);
  if (v < 0.0 || v > 1e9 || v != std::floor(v))
    throw std::invalid_argument("expected a whole number, got '" + text + "'");
  return static_cast<std::uint32_t>(v);
}

int axis_of(const std::string& text) {
  if (text == "x") return 0;
  if (text == "y") return 1;
  if (text == "z") return 2;
  throw std::invalid_argument("expected axis x, y or z, got '" + text + "'");
}

ecs::Entity selection(EditorSession& s) {
  const std::optional<ecs::Entity> e = s.selected();
  if (!e) throw std::invalid_argument("nothing is selected");
  return *e;
}

std::string selected_name(EditorSession& s) {
  const std::optional<ecs::Entity> e = s.selected();
  if (!e) return "none";
  const Name* n = s.registry().try_get<Name>(*e);
  return n != nullptr ? n->value : "entity " + std::to_string(e->index);
}

void run_line(EditorSession& s, const std::vector<std::string>& w,
              const std::function<void()>& on_frame) {
  const std::string& op = w[0];
  const auto want = [&](std::size_t min, std::size_t max, const char* usage) {
    if (w.size() < min + 1 || w.size() > max + 1)
      throw std::invalid_argument("usage: " + std::string(usage));
  };
  if (op == "frames") {
    want(1, 1, "frames N");
    for (std::uint32_t i = count(w[1]); i > 0; --i) {
      s.tick();
      if (on_frame) on_frame();
    }
  } else if (op == "click") {
    want(2, 2, "click X Y");
    (void)s.click(count(w[1]), count(w[2]));
  } else if (op == "select") {
    want(1, 1, "select NAME");
    s.select_by_name(w[1]);
  } else if (op == "deselect") {
    want(0, 0, "deselect");
    s.clear_selection();
  } else if (op == "drag" || op == "rotate" || op == "scale") {
    want(3, 3, "drag|rotate|scale AXIS DX DY");
    const GizmoMode mode = op == "drag"     ? GizmoMode::Translate
                           : op == "rotate" ? GizmoMode::Rotate
                                            : GizmoMode::Scale;
    const int axis = axis_of(w[1]);
    s.drag(mode, axis, dvec2(number(w[2]), number(w[3])));
  } else if (op == "set") {
    want(2, 2, "set PATH VALUE");
    s.set_field(selection(s), w[1], w[2]);
  } else if (op == "add") {
    want(3, 3, "add primitive KIND NAME | add mesh FILE NAME");
    if (w[1] == "primitive")
      (void)s.add_primitive(w[2], w[3]);
    else if (w[1] == "mesh")
      (void)s.add_mesh_file(w[2], w[3]);
    else
      throw std::invalid_argument("expected 'primitive' or 'mesh' after add, got '" + w[1] + "'");
  } else if (op == "delete") {
    want(0, 0, "delete");
    s.remove(selection(s));
  } else if (op == "reparent") {
    want(1, 1, "reparent NAME|none");
    const ecs::Entity child = selection(s);
    ecs::Entity parent = ecs::null_entity;
    if (w[1] != "none") {
      s.select_by_name(w[1]);
      parent = *s.selected();
      s.select(child);
    }
    s.reparent(child, parent);
  } else if (op == "undo" || op == "redo") {
    want(0, 0, "undo | redo");
    if (!(op == "undo" ? s.undo() : s.redo())) throw std::invalid_argument("nothing to " + op);
  } else if (op == "save") {
    want(1, 1, "save PATH");
    s.save(w[1]);
  } else if (op == "screenshot") {
    want(1, 1, "screenshot PATH");
    s.screenshot(w[1]);
  } else if (op == "backend") {
    want(1, 1, "backend NAME");
    s.set_backend(w[1]);
  } else if (op == "mode") {
    want(1, 1, "mode cast|whitted|path|shadow");
    const std::optional<TraceMode> m = parse_trace_mode(w[1]);
    if (!m) throw std::invalid_argument("unknown mode '" + w[1] + "'");
    s.set_mode(*m);
  } else if (op == "depth") {
    want(1, 1, "depth N");
    s.set_max_depth(count(w[1]));
  } else if (op == "cache") {
    want(1, 1, "cache off|on");
    cache::CacheSettings c = s.view().cache;
    const std::optional<cache::CachePolicy> p = cache::parse_cache_policy(w[1]);
    if (!p) throw std::invalid_argument("expected off, on or auto, got '" + w[1] + "'");
    c.policy = *p;
    s.set_cache(c);
  } else if (op == "cache-view") {
    want(1, 1, "cache-view off|on");
    if (w[1] != "on" && w[1] != "off")
      throw std::invalid_argument("expected on or off, got '" + w[1] + "'");
    s.set_cache_view(w[1] == "on");
  } else if (op == "orbit") {
    want(2, 2, "orbit DX DY");
    s.set_camera(orbit(s.camera(), number(w[1]), number(w[2])));
  } else if (op == "frame-selected") {
    want(0, 0, "frame-selected");
    s.frame_selected();
  } else if (op == "expect") {
    if (w.size() >= 2 && w[1] == "selected") {
      want(2, 2, "expect selected NAME|none");
      if (selected_name(s) != w[2])
        throw std::invalid_argument("expected selection " + w[2] + ", got " + selected_name(s));
      return;
    }
    want(2, 3, "expect PATH VALUE [TOLERANCE] | expect selected NAME|none");
    const std::string got = get_field(s.snapshot(selection(s)), w[1]);
    bool ok = got == w[2];
    if (!ok && w.size() == 4) {
      const double g = number(got.empty() ? "nan" : got);
      ok = std::abs(g - number(w[2])) <= number(w[3]);
    }
    if (!ok) throw std::invalid_argument("expected " + w[1] + " = " + w[2] + ", got '" + got + "'");
  } else {
    throw std::invalid_argument("unknown action '" + op + "'");
  }
}

} // namespace

void run_script_text(EditorSession& session, const std::string& text, const std::string& name,
                     const std::function<void()>& on_frame) {
  std::istringstream in(text);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    try {
      const std::vector<std::string> words = split(line);
      if (!words.empty()) run_line(session, words, on_frame);
    } catch (const std::exception& e) {
      throw Error(name, number, e.what());
    }
  }
}

void run_script(EditorSession& session, const std::filesystem::path& file,
                const std::function<void()>& on_frame) {
  run_script_text(session, read_file_bounded(file, kMaxScriptBytes, "editor script"), file.string(),
                  on_frame);
}

} // namespace specula::editor
