#include "specula/core/error.h"
#include "specula/trace/integrators.h"

namespace specula::detail {

void shadow_tile(const FrameInputs& /*frame*/, const PacketTile& /*tile*/, TileScratch& /*scratch*/,
               RayCounts& /*counts*/) {
  throw UnavailableError("mode 'shadow' is not available yet");
}

} // namespace specula::detail
