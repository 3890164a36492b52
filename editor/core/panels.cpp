#include "editor/core/panels.h"

#include "editor/core/fields.h"
#include "specula/cache/ray_cache.h"
#include "specula/scene/hierarchy.h"

#include <imgui.h>

#include <algorithm>
#include <cfloat>
#include <charconv>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>

namespace specula::editor {

namespace {

/// Runs an action, keeping its error for the status line instead of ending the editor.
void act(PanelState& state, const std::function<void()>& action) {
  try {
    action();
    state.status.clear();
  } catch (const std::exception& e) {
    state.status = e.what();
  }
}

/// An entity as a widget label: its entity_label, made unique by its editor id (after ##,
/// which ImGui does not show).
std::string label(EditorSession& s, ecs::Entity e) {
  return entity_label(s.registry(), e) + "##" + std::to_string(s.id_of(e));
}

void tree_node(EditorSession& s, PanelState& state, ecs::Entity e,
               const std::multimap<std::uint32_t, ecs::Entity>& children) {
  const auto [first, last] = children.equal_range(e.index);
  ImGuiTreeNodeFlags flags = ImGuiTreeNodeFlags_OpenOnArrow | ImGuiTreeNodeFlags_DefaultOpen;
  if (first == last) flags |= ImGuiTreeNodeFlags_Leaf;
  if (s.selected() == e) flags |= ImGuiTreeNodeFlags_Selected;
  const bool open = ImGui::TreeNodeEx(label(s, e).c_str(), flags);
  if (ImGui::IsItemClicked()) s.select(e);
  if (ImGui::BeginDragDropSource()) {
    const EditorId id = s.id_of(e);
    ImGui::SetDragDropPayload("specula-entity", &id, sizeof id);
    ImGui::TextUnformatted(entity_label(s.registry(), e).c_str());
    ImGui::EndDragDropSource();
  }
  if (ImGui::BeginDragDropTarget()) {
    if (const ImGuiPayload* p = ImGui::AcceptDragDropPayload("specula-entity")) {
      EditorId id = kNoId;
      std::memcpy(&id, p->Data, sizeof id);
      act(state, [&] { s.reparent(s.entity(id), e); });
    }
    ImGui::EndDragDropTarget();
  }
  if (open) {
    for (auto it = first; it != last; ++it) tree_node(s, state, it->second, children);
    ImGui::TreePop();
  }
}

bool combo(const char* name, std::string& value, std::initializer_list<const char*> options) {
  bool changed = false;
  if (ImGui::BeginCombo(name, value.c_str())) {
    for (const char* o : options)
      if (ImGui::Selectable(o, value == o)) {
        value = o;
        changed = true;
      }
    ImGui::EndCombo();
  }
  return changed;
}

} // namespace

PanelLayout panel_layout(float width, float height) {
  const float column = std::clamp(0.25f * width, 180.0f, 320.0f);
  const float right = std::max(0.0f, width - column);
  PanelLayout l;
  const float entities = std::round(0.45f * height);
  l.entities = {0.0f, 0.0f, column, entities};
  l.inspector = {0.0f, entities, column, height - entities};
  const float render = std::min(130.0f, std::round(0.25f * height));
  const float frame = std::round(0.55f * height);
  l.render = {right, 0.0f, column, render};
  l.frame = {right, render, column, frame};
  l.caches = {right, render + frame, column, std::max(0.0f, height - render - frame)};
  return l;
}

namespace {

/// Opens the next panel at its place in panel_layout, the first time only.
void place(PanelRect PanelLayout::*which) {
  const ImVec2 display = ImGui::GetIO().DisplaySize;
  const PanelRect r = panel_layout(display.x, display.y).*which;
  ImGui::SetNextWindowPos(ImVec2(r.x, r.y), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(r.width, r.height), ImGuiCond_FirstUseEver);
}

} // namespace

void entity_tree_panel(EditorSession& s, PanelState& state) {
  place(&PanelLayout::entities);
  ImGui::Begin("Entities");
  std::multimap<std::uint32_t, ecs::Entity> children; // by parent index
  std::vector<ecs::Entity> roots;
  s.registry().each_entity([&](ecs::Entity e) {
    if (const Parent* p = s.registry().try_get<Parent>(e))
      children.emplace(p->entity.index, e);
    else
      roots.push_back(e);
  });
  // The buttons first: a long tree scrolls below them instead of pushing them out of view.
  if (ImGui::Button("Add sphere")) act(state, [&] { (void)s.add_primitive("sphere", "sphere"); });
  ImGui::SameLine();
  if (ImGui::Button("Add box")) act(state, [&] { (void)s.add_primitive("box", "box"); });
  ImGui::SameLine();
  if (ImGui::Button("Delete") && s.selected()) act(state, [&] { s.remove(*s.selected()); });
  if (ImGui::Button("Undo")) s.undo();
  ImGui::SameLine();
  if (ImGui::Button("Redo")) s.redo();
  if (!state.status.empty()) ImGui::TextWrapped("%s", state.status.c_str());
  ImGui::Separator();
  ImGui::TextUnformatted("(scene root: drop here to unparent)");
  if (ImGui::BeginDragDropTarget()) {
    if (const ImGuiPayload* p = ImGui::AcceptDragDropPayload("specula-entity")) {
      EditorId id = kNoId;
      std::memcpy(&id, p->Data, sizeof id);
      act(state, [&] { s.reparent(s.entity(id), ecs::null_entity); });
    }
    ImGui::EndDragDropTarget();
  }
  for (const ecs::Entity e : roots) tree_node(s, state, e, children);
  ImGui::End();
}

void inspector_panel(EditorSession& s, PanelState& state) {
  place(&PanelLayout::inspector);
  ImGui::Begin("Inspector");
  const std::optional<ecs::Entity> e = s.selected();
  if (!e) {
    ImGui::TextUnformatted("nothing selected");
    ImGui::End();
    return;
  }
  ImGui::TextUnformatted(entity_label(s.registry(), *e).c_str());
  const EntitySnapshot snap = s.snapshot(*e);
  // Values a third of the width, the field paths ("Transform.translation.x") in the rest.
  ImGui::PushItemWidth(std::max(60.0f, 0.35f * ImGui::GetContentRegionAvail().x));
  for (const std::string& path : field_paths()) {
    std::string value = get_field(snap, path);
    if (path == "RayCacheCube.enabled") {
      bool on = value == "1";
      if (ImGui::Checkbox(path.c_str(), &on))
        act(state, [&] { s.set_field(*e, path, on ? "1" : "0"); });
      continue;
    }
    if (value.empty()) continue; // the entity lacks the component
    if (path == "Kinematics.type") {
      if (combo(path.c_str(), value, {"static", "hierarchical", "free"}))
        act(state, [&] { s.set_field(*e, path, value); });
    } else if (path == "Light.type") {
      if (combo(path.c_str(), value, {"point", "directional", "spot"}))
        act(state, [&] { s.set_field(*e, path, value); });
    } else {
      double v = 0.0;
      std::from_chars(value.data(), value.data() + value.size(), v);
      // One edit (one undo step) per committed value, not per keystroke.
      if (ImGui::InputDouble(path.c_str(), &v, 0.0, 0.0, "%.6g",
                             ImGuiInputTextFlags_EnterReturnsTrue)) {
        char buf[64];
        const auto r = std::to_chars(buf, buf + sizeof buf, v);
        act(state, [&] { s.set_field(*e, path, std::string(buf, r.ptr)); });
      }
    }
  }
  ImGui::PopItemWidth();
  if (ImGui::Button("Frame selected")) s.frame_selected();
  ImGui::End();
}

void render_settings_panel(EditorSession& s, PanelState& state) {
  place(&PanelLayout::render);
  ImGui::Begin("Render");
  const ViewSettings& v = s.view();
  std::string backend = s.registry().resource<RenderJob>().backend;
  if (ImGui::BeginCombo("backend", backend.c_str())) {
    for (const BackendInfo& b : backends())
      if (b.available && ImGui::Selectable(std::string(b.name).c_str(), backend == b.name))
        act(state, [&] { s.set_backend(std::string(b.name)); });
    ImGui::EndCombo();
  }
  std::string mode = trace_mode_name(v.mode);
  if (combo("mode", mode, {"cast", "whitted", "path", "shadow"}))
    act(state, [&] { s.set_mode(*parse_trace_mode(mode)); });
  int depth = int(v.max_depth.value_or(0));
  if (ImGui::SliderInt("depth", &depth, 0, 16))
    act(state, [&] { s.set_max_depth(std::uint32_t(depth)); });
  bool caches = v.cache.policy != cache::CachePolicy::Off;
  if (ImGui::Checkbox("ray caches", &caches)) {
    cache::CacheSettings c = v.cache;
    c.policy = caches ? cache::CachePolicy::On : cache::CachePolicy::Off;
    act(state, [&] { s.set_cache(c); });
  }
  ImGui::End();
}

void overlay_panel(EditorSession& s) {
  place(&PanelLayout::frame);
  ImGui::Begin("Frame");
  const auto& h = s.history();
  if (h.empty()) {
    ImGui::End();
    return;
  }
  std::vector<float> series(h.size());
  const auto names = Schedule::system_names();
  // Room right of each plot for its label ("acceleration ms").
  ImGui::PushItemWidth(-9.0f * ImGui::GetFontSize());
  for (std::size_t k = 0; k < names.size(); ++k) {
    for (std::size_t i = 0; i < h.size(); ++i)
      series[i] = k < h[i].system_ms.size() ? float(h[i].system_ms[k]) : 0.0f;
    const std::string title = std::string(names[k]) + " ms";
    ImGui::PlotLines(title.c_str(), series.data(), int(series.size()), 0,
                     (std::to_string(series.back()).substr(0, 6)).c_str(), 0.0f, FLT_MAX,
                     ImVec2(0, 30));
  }
  for (std::size_t i = 0; i < h.size(); ++i) series[i] = float(h[i].rays_per_second * 1e-6);
  ImGui::PlotLines("Mrays/s", series.data(), int(series.size()), 0, nullptr, 0.0f, FLT_MAX,
                   ImVec2(0, 40));
  ImGui::PopItemWidth();
  ImGui::Text("frame %.2f ms", h.back().ms);
  ImGui::End();
}

void cache_panel(EditorSession& s) {
  const auto* caches = s.registry().try_resource<cache::RayCaches>();
  if (caches == nullptr || !caches->store) return;
  place(&PanelLayout::caches);
  ImGui::Begin("Ray caches");
  const cache::RayCacheStore& store = *caches->store;
  for (std::size_t i = 0; i < store.cube_count(); ++i) {
    const cache::CubeView c = store.cube(i);
    std::size_t valid = 0;
    for (const cache::Texel& t : c.texels) valid += t.valid() ? 1 : 0;
    ImGui::Text("%s: %zu valid, %zu outdated (%ux%u x6)%s",
                entity_label(s.registry(), c.owner).c_str(), valid, c.texels.size() - valid,
                c.resolution, c.resolution, c.enabled ? "" : ", off");
  }
  bool view = s.cache_view();
  if (ImGui::Checkbox("texels on the objects", &view)) s.set_cache_view(view);
  if (s.cache_view()) {
    const CacheViewCounts& n = s.cache_view_counts();
    ImGui::Text("pixels: %llu valid (green), %llu outdated (red), %llu refused by parallax "
                "(yellow), %llu off (grey)",
                static_cast<unsigned long long>(n.valid),
                static_cast<unsigned long long>(n.outdated),
                static_cast<unsigned long long>(n.rejected),
                static_cast<unsigned long long>(n.off));
  }
  if (const std::optional<ecs::Entity> e = s.selected())
    if (const std::optional<std::size_t> i = store.cube_of(*e)) {
      ImGui::Separator();
      ImGui::TextUnformatted("visibility edges of the selection (entity: texels)");
      for (const auto& [entity, texels] : store.edges(*i)) ImGui::Text("  %u: %u", entity, texels);
    }
  ImGui::End();
}

void draw_panels(EditorSession& session, PanelState& state) {
  entity_tree_panel(session, state);
  inspector_panel(session, state);
  render_settings_panel(session, state);
  overlay_panel(session);
  cache_panel(session);
}

HeadlessUi::HeadlessUi(float width, float height) {
  ImGui::CreateContext();
  ImGuiIO& io = ImGui::GetIO();
  io.DisplaySize = ImVec2(width, height);
  io.IniFilename = nullptr; // no imgui.ini written by tests
  unsigned char* pixels = nullptr;
  int w = 0, h = 0;
  io.Fonts->GetTexDataAsRGBA32(&pixels, &w, &h);
}

HeadlessUi::~HeadlessUi() { ImGui::DestroyContext(); }

void HeadlessUi::frame(EditorSession& session) {
  ImGui::GetIO().DeltaTime = 1.0f / 60.0f;
  ImGui::NewFrame();
  draw_panels(session, state_);
  ImGui::Render();
}

} // namespace specula::editor
