#include "geometry/primitives.h"
#include "core/error.h"
namespace specula {
TriangleMesh make_primitive(const MeshSource&, const std::string& context) {
  throw Error(context, "primitives: not implemented yet");
}
} // namespace specula
