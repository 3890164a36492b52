// stb_image's implementation, from Debian's libstb-dev header, compiled into the PNG fuzzer
// programs (SPECULA_BUILD_FUZZERS only): libstb.so is built without coverage or ASan, so without
// this copy the fuzzer would see none of the decoder's branches and ASan none of its memory
// accesses. The program's definitions take precedence over the shared library's (ELF symbol
// interposition), so the engine's read_png runs this code. Third-party code: no warnings.
#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>
