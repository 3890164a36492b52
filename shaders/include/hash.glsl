// engine/trace/sampler.h's integer hashes, bit for bit (the sampler's seeds, the ray cache's
// choice of verified lookups).
#ifndef SPECULA_HASH_GLSL
#define SPECULA_HASH_GLSL

uint hash_u32(uint x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

uint hash_combine(uint seed, uint v) {
  return hash_u32(seed ^ (v + 0x9e3779b9u + (seed << 6) + (seed >> 2)));
}

#endif
