// Mesh files (OBJ, PLY, OFF, STL): good files give the geometry their text describes, bad files
// give a specula::Error naming the file and the problem, never a crash or a silently wrong mesh.
// The small files live in tests/data/mesh/ (binary ones from make_binary_files.py there); real
// files come from Debian's assimp-testmodels when installed.

#include "specula/scene/mesh_io.h"

#include "specula/core/error.h"

#include <gtest/gtest.h>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace specula {
namespace {

namespace fs = std::filesystem;

const fs::path kMeshData = fs::path(SPECULA_TEST_DATA_DIR) / "mesh";
const fs::path kAssimpModels = "/usr/share/assimp/models";

/// The message of the Error that loading `path` throws (fails the test if it does not throw).
std::string load_error(const fs::path& path) {
  try {
    (void)load_mesh_file(path);
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << path << " loaded without an error";
  return {};
}

/// GoogleTest name of a parameter naming a file: "out_of_range_index.obj" ->
/// "out_of_range_index_obj".
std::string file_test_name(std::string name) {
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return name;
}

/// A fresh scratch directory for one test, removed at the end.
class ScratchDir {
public:
  explicit ScratchDir(const std::string& name)
      : path_(fs::temp_directory_path() / ("specula_test_mesh_io_" + name)) {
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~ScratchDir() { fs::remove_all(path_); }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  [[nodiscard]] const fs::path& path() const { return path_; }

private:
  fs::path path_;
};

void expect_unit_normals(const TriangleMesh& mesh, const std::string& what) {
  ASSERT_EQ(mesh.normals.size(), mesh.positions.size()) << what;
  for (std::size_t i = 0; i < mesh.normals.size(); ++i)
    ASSERT_NEAR(glm::length(mesh.normals[i]), 1.0f, 1e-4f) << what << ": vertex " << i;
}

void expect_bounds(const TriangleMesh& mesh, vec3 min, vec3 max, const std::string& what) {
  const Aabb box = mesh.bounds();
  for (int k = 0; k < 3; ++k) {
    EXPECT_FLOAT_EQ(box.min[k], min[k]) << what << " axis " << k;
    EXPECT_FLOAT_EQ(box.max[k], max[k]) << what << " axis " << k;
  }
}

/// Geometric (unnormalised) normal of triangle t.
vec3 face_normal(const TriangleMesh& mesh, std::size_t t) {
  const uvec3 tri = mesh.triangles[t];
  return glm::cross(mesh.positions[tri.y] - mesh.positions[tri.x],
                    mesh.positions[tri.z] - mesh.positions[tri.x]);
}

/// Every triangle of a closed convex mesh faces away from `center` (winding kept from the file).
void expect_outward(const TriangleMesh& mesh, vec3 center, const std::string& what) {
  for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
    const uvec3 tri = mesh.triangles[t];
    const vec3 centroid =
        (mesh.positions[tri.x] + mesh.positions[tri.y] + mesh.positions[tri.z]) / 3.0f;
    EXPECT_GT(glm::dot(face_normal(mesh, t), centroid - center), 0.0f) << what << " triangle " << t;
  }
}

// ---- Extensions -----------------------------------------------------------------------------

TEST(MeshIo, ExtensionsAreRecognisedWithoutRegardToCase) {
  for (const char* ext : {".obj", ".ply", ".off", ".stl", ".OBJ", ".Ply", ".oFF", ".STL"})
    EXPECT_TRUE(is_mesh_file_extension(ext)) << ext;
  for (const char* ext : {"", ".", ".gltf", ".xyz", ".objx", "obj", ".st"})
    EXPECT_FALSE(is_mesh_file_extension(ext)) << ext;
}

TEST(MeshIo, UpperCaseExtensionLoads) {
  const ScratchDir dir("upper");
  const fs::path upper = dir.path() / "CUBE.OBJ";
  fs::copy_file(kMeshData / "cube.obj", upper);
  EXPECT_EQ(load_mesh_file(upper).triangle_count(), 12u);
}

// ---- Good files -----------------------------------------------------------------------------

// The unit cube [0,1]^3 as 8 vertices and 6 outward quads (or 12 triangles), in every format.
class UnitCubeFile : public testing::TestWithParam<const char*> {};

TEST_P(UnitCubeFile, IsTwelveOutwardTrianglesFillingTheUnitCube) {
  const TriangleMesh mesh = load_mesh_file(kMeshData / GetParam());
  EXPECT_EQ(mesh.triangle_count(), 12u);
  // No normals or texture coordinates in these files, so no vertex needs splitting; the binary
  // STL repeats each corner per facet and OpenMesh's STL reader merges them.
  EXPECT_EQ(mesh.vertex_count(), 8u);
  EXPECT_TRUE(mesh.uvs.empty());
  expect_bounds(mesh, vec3(0.0f), vec3(1.0f), GetParam());
  expect_outward(mesh, vec3(0.5f), GetParam());
  expect_unit_normals(mesh, GetParam());
  // Smooth normals of a cube corner point out along the diagonal through it.
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i)
    EXPECT_GT(glm::dot(mesh.normals[i], mesh.positions[i] - vec3(0.5f)), 0.0f) << "vertex " << i;
  EXPECT_NO_THROW(mesh.validate(GetParam()));
}

INSTANTIATE_TEST_SUITE_P(AllFormats, UnitCubeFile,
                         testing::Values("cube.obj", "cube.off", "cube_binary.off",
                                         "cube_ascii.ply", "cube_binary.ply", "cube_binary.stl"));

TEST(MeshIo, AsciiStlTriangleHasItsCornersAndFacingNormal) {
  const TriangleMesh mesh = load_mesh_file(kMeshData / "tri.stl");
  ASSERT_EQ(mesh.triangle_count(), 1u);
  EXPECT_EQ(mesh.vertex_count(), 3u);
  expect_bounds(mesh, vec3(0.0f), vec3(2.0f, 3.0f, 0.0f), "tri.stl");
  // Corners (0,0,0), (2,0,0), (0,3,0) wind counter-clockwise seen from +Z.
  for (const vec3& n : mesh.normals) EXPECT_NEAR(glm::distance(n, vec3(0, 0, 1)), 0.0f, 1e-6f);
}

TEST(MeshIo, ObjTextureCoordinatesAndNormalsAreKept) {
  const TriangleMesh mesh = load_mesh_file(kMeshData / "quad_uv.obj");
  ASSERT_EQ(mesh.triangle_count(), 2u);
  ASSERT_EQ(mesh.vertex_count(), 4u);
  ASSERT_EQ(mesh.uvs.size(), 4u);
  // The file gives each corner the texture coordinate equal to its (x, y) and the normal +Z.
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
    EXPECT_EQ(mesh.uvs[i], vec2(mesh.positions[i].x, mesh.positions[i].y)) << "vertex " << i;
    EXPECT_EQ(mesh.normals[i], vec3(0, 0, 1)) << "vertex " << i;
  }
  expect_bounds(mesh, vec3(0.0f), vec3(1.0f, 1.0f, 0.0f), "quad_uv.obj");
}

TEST(MeshIo, OffNormalsAndTextureCoordinatesAreKept) {
  // normals.off (NOFF): a triangle wound towards +Z whose file normals all say -Z; the file's
  // normals win over computed ones.
  const TriangleMesh with_normals = load_mesh_file(kMeshData / "normals.off");
  ASSERT_EQ(with_normals.triangle_count(), 1u);
  for (const vec3& n : with_normals.normals) EXPECT_EQ(n, vec3(0, 0, -1));
  // texcoords.off (STOFF): each vertex's texture coordinate is its (x, y).
  const TriangleMesh with_uvs = load_mesh_file(kMeshData / "texcoords.off");
  ASSERT_EQ(with_uvs.uvs.size(), with_uvs.vertex_count());
  for (std::size_t i = 0; i < with_uvs.vertex_count(); ++i)
    EXPECT_EQ(with_uvs.uvs[i], vec2(with_uvs.positions[i].x, with_uvs.positions[i].y));
}

TEST(MeshIo, PerFaceObjNormalsSplitSharedPositions) {
  const TriangleMesh mesh = load_mesh_file(kMeshData / "cube_face_normals.obj");
  EXPECT_EQ(mesh.triangle_count(), 12u);
  // Each of the 8 corners touches 3 faces with 3 different normals.
  EXPECT_EQ(mesh.vertex_count(), 24u);
  expect_unit_normals(mesh, "cube_face_normals.obj");
  // Each triangle's vertices carry the file's normal of its face, which is its facing direction.
  for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
    const vec3 facing = glm::normalize(face_normal(mesh, t));
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(glm::distance(mesh.normals[mesh.triangles[t][k]], facing), 0.0f, 1e-6f)
          << "triangle " << t << " corner " << k;
  }
}

TEST(MeshIo, NonManifoldFacesKeepTheirVerticesAndTextureCoordinates) {
  const TriangleMesh mesh = load_mesh_file(kMeshData / "nonmanifold_uv.obj");
  EXPECT_EQ(mesh.triangle_count(), 3u);
  // No copies: three faces around one edge still use the file's 5 vertices.
  EXPECT_EQ(mesh.vertex_count(), 5u);
  ASSERT_EQ(mesh.uvs.size(), mesh.vertex_count());
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i)
    EXPECT_EQ(mesh.uvs[i], vec2(mesh.positions[i].x, mesh.positions[i].y)) << "vertex " << i;
}

TEST(MeshIo, DegenerateTrianglesNextToProperOnesAreKept) {
  const TriangleMesh mesh = load_mesh_file(kMeshData / "with_degenerate.obj");
  ASSERT_EQ(mesh.triangle_count(), 2u);
  std::size_t zero_area = 0;
  for (std::size_t t = 0; t < mesh.triangle_count(); ++t)
    zero_area += glm::length(face_normal(mesh, t)) == 0.0f ? 1 : 0;
  EXPECT_EQ(zero_area, 1u);
  expect_bounds(mesh, vec3(0.0f), vec3(2.0f, 1.0f, 0.0f), "with_degenerate.obj");
  expect_unit_normals(mesh, "with_degenerate.obj");
}

// ---- Bad files ------------------------------------------------------------------------------

struct BadFile {
  const char* name;
  const char* problem; ///< a word the message must contain
};

class BadMeshFile : public testing::TestWithParam<BadFile> {};

TEST_P(BadMeshFile, ThrowsAnErrorNamingTheFileAndTheProblem) {
  const std::string message = load_error(kMeshData / GetParam().name);
  EXPECT_NE(message.find(GetParam().name), std::string::npos) << message;
  EXPECT_NE(message.find(GetParam().problem), std::string::npos) << message;
}

INSTANTIATE_TEST_SUITE_P(
    Data, BadMeshFile,
    testing::Values(
        BadFile{"empty.obj", "empty"}, BadFile{"truncated.ply", "truncated"},
        BadFile{"truncated_binary.stl", "truncated"}, BadFile{"binary_garbage.stl", "not an STL"},
        BadFile{"malformed.obj", "not a number"}, BadFile{"nan_vertex.obj", "NaN"},
        BadFile{"nan_vertex.ply", "NaN"}, BadFile{"inf_vertex.off", "Inf"},
        BadFile{"out_of_range_index.obj", "out of range"},
        BadFile{"out_of_range_index.off", "out of range"},
        BadFile{"out_of_range_index.ply", "out of range"},
        BadFile{"out_of_range_index_binary.ply", "out of range"},
        BadFile{"absurd_count.off", "more than the limit"},
        BadFile{"absurd_count.ply", "absurd count"},
        BadFile{"absurd_count_binary.off", "more than the limit"},
        BadFile{"no_faces.obj", "no faces"}, BadFile{"cube.xyz", "extension"},
        BadFile{"degenerate_only.obj", "degenerate"}, BadFile{"comment.off", "comment"},
        BadFile{"missing_edge_count.off", "edge count"},
        BadFile{"face_colour_without_coff.off", "need a 'COFF' header"},
        BadFile{"bad_version.ply", "format"}, BadFile{"negative_list_length.ply", "negative"},
        BadFile{"end_header_whitespace.ply", "whitespace"},
        BadFile{"float_overflow.obj", "float range"}, BadFile{"nan_vertex_binary.stl", "NaN"},
        BadFile{"face_texcoord_list.ply", "list property"}),
    [](const testing::TestParamInfo<BadFile>& param) { return file_test_name(param.param.name); });

TEST(MeshIo, MissingFileIsAnError) {
  const std::string message = load_error(kMeshData / "no_such_mesh.obj");
  EXPECT_NE(message.find("no_such_mesh.obj"), std::string::npos) << message;
  EXPECT_NE(message.find("not found"), std::string::npos) << message;
}

TEST(MeshIo, DirectoryIsAnError) {
  const ScratchDir dir("directory");
  const fs::path folder = dir.path() / "folder.obj";
  fs::create_directory(folder);
  const std::string message = load_error(folder);
  EXPECT_NE(message.find("folder.obj"), std::string::npos) << message;
  EXPECT_NE(message.find("directory"), std::string::npos) << message;
}

TEST(MeshIo, UnreadableFileIsAnError) {
  const ScratchDir dir("unreadable");
  const fs::path file = dir.path() / "locked.obj";
  fs::copy_file(kMeshData / "cube.obj", file);
  fs::permissions(file, fs::perms::none);
  if (std::ifstream(file).is_open()) GTEST_SKIP() << "permissions are not enforced (root?)";
  const std::string message = load_error(file);
  EXPECT_NE(message.find("locked.obj"), std::string::npos) << message;
  EXPECT_NE(message.find("cannot open"), std::string::npos) << message;
}

// ---- Real files (Debian assimp-testmodels) ---------------------------------------------------

class AssimpModel : public testing::TestWithParam<const char*> {
protected:
  void SetUp() override {
    if (!fs::is_directory(kAssimpModels)) GTEST_SKIP() << kAssimpModels << " not installed";
  }
};

TEST_P(AssimpModel, LoadsAValidMeshWithUnitNormals) {
  const fs::path path = kAssimpModels / GetParam();
  const TriangleMesh mesh = load_mesh_file(path);
  EXPECT_GT(mesh.triangle_count(), 0u);
  EXPECT_NO_THROW(mesh.validate(path.string()));
  const Aabb box = mesh.bounds();
  EXPECT_FALSE(box.empty());
  EXPECT_TRUE(is_finite(box.min) && is_finite(box.max));
  expect_unit_normals(mesh, GetParam());
  EXPECT_TRUE(mesh.uvs.empty() || mesh.uvs.size() == mesh.vertex_count());
}

INSTANTIATE_TEST_SUITE_P(Real, AssimpModel,
                         testing::Values("OBJ/spider.obj", "OBJ/box.obj", "OBJ/WusonOBJ.obj",
                                         "PLY/cube.ply", "PLY/cube_binary.ply", "PLY/cube_uv.ply",
                                         "PLY/Wuson.ply", "STL/Spider_binary.stl",
                                         "STL/Spider_ascii.stl", "STL/3DSMaxExport.STL",
                                         "OFF/Cube.off", "OFF/Wuson.off"),
                         [](const testing::TestParamInfo<const char*>& param) {
                           return file_test_name(param.param);
                         });

TEST(MeshIoAssimp, BoxObjIsTheCubeOfHalfExtentOneHalf) {
  if (!fs::is_directory(kAssimpModels)) GTEST_SKIP() << kAssimpModels << " not installed";
  // box.obj: 8 vertices at (+-0.5, +-0.5, +-0.5), 6 quads.
  const TriangleMesh mesh = load_mesh_file(kAssimpModels / "OBJ/box.obj");
  EXPECT_EQ(mesh.triangle_count(), 12u);
  expect_bounds(mesh, vec3(-0.5f), vec3(0.5f), "box.obj");
}

TEST(MeshIoAssimp, AsciiAndBinarySpiderStlAgree) {
  if (!fs::is_directory(kAssimpModels)) GTEST_SKIP() << kAssimpModels << " not installed";
  const TriangleMesh ascii = load_mesh_file(kAssimpModels / "STL/Spider_ascii.stl");
  const TriangleMesh binary = load_mesh_file(kAssimpModels / "STL/Spider_binary.stl");
  EXPECT_EQ(ascii.triangle_count(), binary.triangle_count());
  EXPECT_EQ(ascii.vertex_count(), binary.vertex_count());
  const Aabb a = ascii.bounds();
  const Aabb b = binary.bounds();
  // The ASCII file prints fewer digits than the floats of the binary one.
  EXPECT_LT(glm::distance(a.min, b.min), 1e-3f);
  EXPECT_LT(glm::distance(a.max, b.max), 1e-3f);
}

TEST(MeshIoAssimp, OpenMeshWarningsDoNotReachTheConsole) {
  if (!fs::is_directory(kAssimpModels)) GTEST_SKIP() << kAssimpModels << " not installed";
  // box.obj names a material its .mtl does not define, which OpenMesh reports on omerr;
  // Wuson.ply has a stray header line, which it reports too.
  testing::internal::CaptureStderr();
  testing::internal::CaptureStdout();
  (void)load_mesh_file(kAssimpModels / "OBJ/box.obj");
  (void)load_mesh_file(kAssimpModels / "PLY/Wuson.ply");
  const std::string err = testing::internal::GetCapturedStderr();
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_EQ(err, "");
  EXPECT_EQ(out, "");
}

class AssimpInvalidModel : public testing::TestWithParam<const char*> {
protected:
  void SetUp() override {
    if (!fs::is_directory(kAssimpModels)) GTEST_SKIP() << kAssimpModels << " not installed";
  }
};

TEST_P(AssimpInvalidModel, IsAnErrorNamingTheFile) {
  const fs::path path = kAssimpModels / "invalid" / GetParam();
  const std::string message = load_error(path);
  EXPECT_NE(message.find(GetParam()), std::string::npos) << message;
}

INSTANTIATE_TEST_SUITE_P(Invalid, AssimpInvalidModel,
                         testing::Values("empty.obj", "malformed.obj", "malformed2.obj",
                                         "empty.ply", "empty.off", "OutOfMemory.off"),
                         [](const testing::TestParamInfo<const char*>& param) {
                           return file_test_name(param.param);
                         });

// ---- Concurrency ----------------------------------------------------------------------------

TEST(MeshIo, ConcurrentLoadsAllSucceedOrFailCleanly) {
  // OpenMesh's log streams are process-wide; loads from several threads must not interfere.
  std::vector<std::thread> threads;
  std::vector<int> loaded(4, 0);
  std::vector<int> failed(4, 0);
  for (std::size_t i = 0; i < loaded.size(); ++i)
    threads.emplace_back([&, i] {
      for (int round = 0; round < 10; ++round) {
        loaded[i] +=
            load_mesh_file(kMeshData / (i % 2 ? "cube.off" : "cube.obj")).triangle_count() == 12u;
        try {
          (void)load_mesh_file(kMeshData / "out_of_range_index_binary.ply");
        } catch (const Error&) {
          ++failed[i];
        }
      }
    });
  for (std::thread& t : threads) t.join();
  for (std::size_t i = 0; i < loaded.size(); ++i) {
    EXPECT_EQ(loaded[i], 10) << "thread " << i;
    EXPECT_EQ(failed[i], 10) << "thread " << i;
  }
}

} // namespace
} // namespace specula
