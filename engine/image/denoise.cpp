#include "specula/image/denoise.h"

#include "specula/core/error.h"

namespace specula {

void atrous_denoise(const Framebuffer& /*noisy*/, const GuideBuffers& /*guides*/,
                    const DenoiseSettings& /*settings*/, Framebuffer& /*out*/) {
  throw UnavailableError("the à-trous denoiser is not implemented yet");
}

} // namespace specula
