#include "specula/image/srgb.h"

namespace specula {

const Srgb8Encoder& Srgb8Encoder::get() {
  static const Srgb8Encoder encoder;
  return encoder;
}

Srgb8Encoder::Srgb8Encoder() {
  constexpr std::uint32_t one = 0x3f800000u; // 1.0f
  threshold_[0] = 0.0f;
  // The least bit pattern in [+0, 1.0f] whose reference code is at least k (the reference reaches
  // 255 at 1.0f, so one exists; floats of one sign order as their bit patterns).
  for (std::uint32_t k = 1; k < 256; ++k) {
    std::uint32_t lo = 0, hi = one;
    while (lo < hi) {
      const std::uint32_t mid = lo + (hi - lo) / 2;
      if (encode_srgb8_reference(std::bit_cast<float>(mid)) >= k)
        hi = mid;
      else
        lo = mid + 1;
    }
    threshold_[k] = std::bit_cast<float>(lo);
  }
  threshold_[256] = 2.0f;
  for (std::uint32_t run = 0; run < kRuns; ++run)
    run_code_[run] = encode_srgb8_reference(std::bit_cast<float>(run << kRunShift));
}

} // namespace specula
