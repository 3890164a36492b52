// tinygltf's implementation, from Debian's libtinygltf-dev header, compiled into the glTF and GLB
// fuzzer programs (SPECULA_BUILD_FUZZERS only), for the reason instrumented_stb_image.cpp gives:
// libtinygltf.so has no coverage or ASan instrumentation, and the program's definitions take
// precedence over it. Same defines as the engine's include (none), so the classes agree; images
// are decoded by stb_image (the engine skips them anyway). Third-party code: no warnings.
#define TINYGLTF_IMPLEMENTATION
#include <tiny_gltf.h>
