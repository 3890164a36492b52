// run_window for builds without specula::present (no Vulkan or GLFW): headless only.
#include "editor/editor_window.h"

#include "specula/core/error.h"

namespace specula::editor {

int run_window(EditorSession& /*session*/, const WindowRun& /*run*/) {
  throw UnavailableError("this build has no windowed editor (specula::present): use --headless");
}

std::unique_ptr<UiCapture> UiCapture::create(std::uint32_t /*width*/, std::uint32_t /*height*/) {
  throw UnavailableError("this build cannot draw the editor's panels (no specula::present): "
                         "--screenshot-ui needs it");
}

} // namespace specula::editor
