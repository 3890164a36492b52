// Harness for the bare mesh readers (OBJ, PLY, OFF, STL through OpenMesh and Specula's pre-scan):
// load_mesh_file, and its promise that what it returns is valid (finite values, indices in
// range, at least one triangle). SPECULA_FUZZ_FILE names the scratch file, and so the format.

#include "fuzz_support.h"

#include "specula/scene/mesh_io.h"

#ifndef SPECULA_FUZZ_FILE
#error "define SPECULA_FUZZ_FILE (e.g. \"mesh.obj\")"
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path path = specula::fuzz::write_input({data, size}, SPECULA_FUZZ_FILE);
  specula::fuzz::expect_only_errors([&] {
    const specula::TriangleMesh mesh = specula::load_mesh_file(path);
    try {
      mesh.validate(path.string());
    } catch (const specula::Error& e) {
      specula::fuzz::finding(std::string("load_mesh_file returned an invalid mesh: ") + e.what());
    }
  });
  return 0;
}
