/// \file
/// Bare mesh files through OpenMesh's readers, behind a scan of our own.
///
/// OpenMesh 9.0 (Debian 12) turns much bad input into silent garbage, hangs or crashes:
///   - absurd counts: the OFF reader reserves them (10^12 vertices aborts on allocation); the PLY
///     header loop never ends on a count beyond 32 bits or a version that is not a number, nor
///     the binary body on a negative or huge "int" list length;
///   - the OBJ reader drops vertices it cannot parse ("nan", "banana", 1e39), shifting every
///     later index; the OFF and ASCII PLY readers desynchronise on them instead;
///   - the OFF reader reads '#' comment lines as data and nothing when the counts share the
///     "OFF" line; it reads three counts wherever they are (a missing edge count is taken from
///     the first vertex) and a face colour only under a 'C' header (otherwise as the next face);
///     either shifts every later number, and a -1 read as a face size asks for 4 G handles
///     (found by fuzzing); binary PLY data is read from a fixed offset after the last header
///     word, so extra whitespace before "end_header" shifts every value;
///   - ImporterT drops faces with out-of-range indices or a repeated vertex (telling only omerr;
///     read_mesh still returns true), and moves non-manifold faces onto copied vertices whose
///     normals and texture coordinates stay uninitialised;
///   - a binary STL whose size does not match its triangle count is parsed as ASCII (an empty
///     mesh, read_mesh returns true); NaN corners vanish in the STL reader's vertex merging;
///   - messages go to the console through omerr/omlog.
/// So each file is first scanned by us (counts against the file size, every OBJ/OFF/ASCII PLY
/// value and index, binary PLY list lengths and indices, STL layout and values). OpenMesh then
/// parses it into RecordingImporter, which keeps the polygons as written; what it read is
/// checked against the scan (faces lost) and by TriangleMesh::validate.

#include "specula/scene/mesh_io.h"

#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/scene/scene.h"

// OpenMesh's headers are found under /usr/include, so GCC treats them as system headers and
// keeps their warnings out of our -Werror build; nothing else is needed around the includes.
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <mutex>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

namespace specula {
namespace {

namespace fs = std::filesystem;
using OmMesh = OpenMesh::PolyMesh_ArrayKernelT<>;

enum class MeshFormat { obj, ply, off, stl };

[[nodiscard]] std::string lower_ascii(std::string_view text) {
  std::string out(text);
  for (char& c : out)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return out;
}

[[nodiscard]] std::optional<MeshFormat> format_of(std::string_view extension) {
  const std::string ext = lower_ascii(extension);
  if (ext == ".obj") return MeshFormat::obj;
  if (ext == ".ply") return MeshFormat::ply;
  if (ext == ".off") return MeshFormat::off;
  if (ext == ".stl") return MeshFormat::stl;
  return std::nullopt;
}

/// What the pre-scan learned about a file, to check OpenMesh's result against.
struct ScanResult {
  /// Polygons the file declares (OBJ 'f' lines, OFF/PLY face counts); empty when not known.
  std::optional<std::uint64_t> declared_faces;
  /// Declared faces that repeat a vertex; OpenMesh drops these as degenerate.
  std::uint64_t faces_with_repeated_vertex = 0;
  /// Triangles the faces seen so far become (n - 2 for a polygon of n corners).
  std::uint64_t triangles = 0;
};

// ---- Text scanning helpers ------------------------------------------------------------------

/// Calls fn(line_number, line) for each line of `text` (LF or CRLF; line numbers from 1).
template <class Fn>
void for_each_line(std::string_view text, Fn&& fn) {
  int line_number = 0;
  while (!text.empty()) {
    const std::size_t end = text.find('\n');
    std::string_view line = text.substr(0, end);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    fn(++line_number, line);
    if (end == std::string_view::npos) break;
    text.remove_prefix(end + 1);
  }
}

[[nodiscard]] bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
}

/// Splits a line at whitespace into `tokens` (cleared first; reused to avoid allocations).
void split_tokens(std::string_view line, std::vector<std::string_view>& tokens) {
  tokens.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (i > start) tokens.push_back(line.substr(start, i - start));
  }
}

/// A floating-point number; from_chars is locale-independent, unlike the streams OpenMesh uses.
/// Accepts "nan" and "inf" so that callers can name them as such.
[[nodiscard]] std::optional<double> parse_number(std::string_view token) {
  if (token.size() > 1 && token.front() == '+') token.remove_prefix(1);
  double value = 0.0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (end != token.data() + token.size()) return std::nullopt;
  // Out of range: 1e-999 underflows to zero (as OpenMesh's stream reads it), 1e999 is as good
  // as infinite for a mesh.
  if (ec == std::errc::result_out_of_range)
    return token.find("e-") != std::string_view::npos || token.find("E-") != std::string_view::npos
               ? 0.0
               : std::numeric_limits<double>::infinity();
  if (ec != std::errc()) return std::nullopt;
  return value;
}

[[nodiscard]] std::optional<std::int64_t> parse_integer(std::string_view token) {
  if (token.size() > 1 && token.front() == '+') token.remove_prefix(1);
  std::int64_t value = 0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (ec != std::errc() || end != token.data() + token.size()) return std::nullopt;
  return value;
}

[[nodiscard]] std::string quote_token(std::string_view token) {
  constexpr std::size_t kMax = 32; // a garbage token may be a whole binary blob
  std::string out = "'";
  for (const char c : token.substr(0, kMax)) // keep control bytes out of messages
    out += c >= ' ' && c <= '~' ? c : '?';
  if (token.size() > kMax) out += "...";
  return out + "'";
}

/// Whether OpenMesh's float streams read `value` as a number: beyond the float range they fail,
/// and the OBJ reader then drops the whole vertex, shifting every later index.
[[nodiscard]] bool fits_float(double value) {
  return std::abs(value) <= static_cast<double>(std::numeric_limits<float>::max());
}

/// Checks the numbers of an OBJ/OFF/STL vertex-like line: all tokens numeric, finite floats.
void check_numbers(const std::string& file, int line, std::span<const std::string_view> tokens,
                   std::string_view what) {
  for (std::string_view token : tokens) {
    const std::optional<double> value = parse_number(token);
    if (!value)
      throw Error(file, line,
                  std::string(what) + " value " + quote_token(token) + " is not a number");
    if (!std::isfinite(*value))
      throw Error(file, line,
                  std::string(what) + " has a non-finite value " + quote_token(token) +
                      " (NaN or Inf)");
    if (!fits_float(*value))
      throw Error(file, line,
                  std::string(what) + " value " + quote_token(token) +
                      " is beyond the float range (Inf as a float)");
  }
}

/// Fails when a mesh declares (or, for OBJ, has reached) more vertices or faces than any mesh
/// may have (kMaxVertices, kMaxTriangles; docs/limits.md): before anything is allocated for them.
/// A face is at least one triangle, so more faces than kMaxTriangles cannot fit either.
void check_mesh_counts(const std::string& file, int line, std::uint64_t vertices,
                       std::uint64_t faces) {
  std::string message;
  if (vertices > kMaxVertices)
    message = std::to_string(vertices) + " vertices, more than the limit of " +
              std::to_string(kMaxVertices);
  else if (faces > kMaxTriangles)
    message = std::to_string(faces) + " faces, more than the limit of " +
              std::to_string(kMaxTriangles) + " triangles";
  else
    return;
  message = "the mesh has " + message + " per mesh (docs/limits.md)";
  if (line > 0) throw Error(file, line, message);
  throw Error(file, message);
}

[[nodiscard]] std::uint32_t read_u32_le(std::string_view bytes, std::size_t at) {
  std::uint32_t v = 0;
  for (std::size_t b = 0; b < 4; ++b)
    v |= std::uint32_t{static_cast<std::uint8_t>(bytes[at + b])} << (8 * b);
  return v;
}

[[nodiscard]] bool has_repeated(std::vector<std::uint64_t>& indices) {
  std::sort(indices.begin(), indices.end());
  return std::adjacent_find(indices.begin(), indices.end()) != indices.end();
}

/// Records a face of the scan (its corners' vertex indices, reordered here): whether it repeats
/// a vertex, and the triangles it becomes, which must stay within kMaxTriangles however few
/// faces the header declares (a face of a million corners is a million triangles less two).
/// `line` 0: a binary file.
void note_face(const std::string& file, int line, std::vector<std::uint64_t>& corners,
               ScanResult& result) {
  if (has_repeated(corners)) ++result.faces_with_repeated_vertex;
  result.triangles += corners.size() - 2;
  if (result.triangles > kMaxTriangles) {
    const std::string message = "the faces become more than the limit of " +
                                std::to_string(kMaxTriangles) +
                                " triangles per mesh (docs/limits.md)";
    if (line > 0) throw Error(file, line, message);
    throw Error(file, message);
  }
}

// ---- OBJ ------------------------------------------------------------------------------------

/// Resolves one OBJ index (1-based, or negative = relative to the end) against `count`
/// elements defined so far.
[[nodiscard]] std::uint64_t resolve_obj_index(const std::string& file, int line,
                                              std::string_view token, std::uint64_t count,
                                              std::string_view what) {
  const std::optional<std::int64_t> index = parse_integer(token);
  if (!index) throw Error(file, line, "face index " + quote_token(token) + " is not an integer");
  if (*index == 0) throw Error(file, line, "face index 0 is out of range (OBJ indices start at 1)");
  const std::uint64_t magnitude = *index > 0 ? static_cast<std::uint64_t>(*index)
                                             : static_cast<std::uint64_t>(-(*index + 1)) + 1;
  if (magnitude > count)
    throw Error(file, line,
                "face index " + std::string(token) + " is out of range: only " +
                    std::to_string(count) + " " + std::string(what) + " defined before this line");
  return *index > 0 ? magnitude - 1 : count - magnitude;
}

/// OBJ: every 'v'/'vt'/'vn' is numeric and finite, every face has three or more corners whose
/// indices refer to elements defined before it (what OpenMesh resolves them against).
[[nodiscard]] ScanResult scan_obj(const std::string& file, std::string_view text) {
  ScanResult result;
  result.declared_faces = 0;
  std::uint64_t positions = 0;
  std::uint64_t texcoords = 0;
  std::uint64_t normals = 0;
  std::vector<std::string_view> tokens;
  std::vector<std::uint64_t> corners;
  for_each_line(text, [&](int line, std::string_view content) {
    content = content.substr(0, content.find('#'));
    split_tokens(content, tokens);
    if (tokens.empty()) return;
    const std::string_view keyword = tokens[0];
    const auto values = std::span<const std::string_view>(tokens).subspan(1);
    if (keyword == "v") {
      // x y z, optionally w or an r g b colour.
      if (values.size() < 3 || values.size() > 7)
        throw Error(file, line,
                    "vertex needs 3 coordinates, found " + std::to_string(values.size()));
      check_numbers(file, line, values, "vertex");
      check_mesh_counts(file, line, ++positions, 0);
    } else if (keyword == "vt") {
      if (values.empty() || values.size() > 3)
        throw Error(file, line, "texture coordinate needs 1 to 3 values");
      check_numbers(file, line, values, "texture coordinate");
      ++texcoords;
    } else if (keyword == "vn") {
      if (values.size() != 3) throw Error(file, line, "normal needs 3 values");
      check_numbers(file, line, values, "normal");
      ++normals;
    } else if (keyword == "f") {
      if (values.size() < 3)
        throw Error(file, line,
                    "face has " + std::to_string(values.size()) + " vertices, at least 3 needed");
      corners.clear();
      for (std::string_view corner : values) {
        // v, v/vt, v//vn or v/vt/vn
        const std::size_t slash1 = corner.find('/');
        corners.push_back(
            resolve_obj_index(file, line, corner.substr(0, slash1), positions, "vertices"));
        if (slash1 == std::string_view::npos) continue;
        const std::string_view rest = corner.substr(slash1 + 1);
        const std::size_t slash2 = rest.find('/');
        const std::string_view vt = rest.substr(0, slash2);
        if (!vt.empty()) (void)resolve_obj_index(file, line, vt, texcoords, "texture coordinates");
        if (slash2 != std::string_view::npos) {
          const std::string_view vn = rest.substr(slash2 + 1);
          if (!vn.empty()) (void)resolve_obj_index(file, line, vn, normals, "normals");
        }
      }
      note_face(file, line, corners, result);
      check_mesh_counts(file, line, 0, ++*result.declared_faces);
    }
    // Everything else (o, g, s, usemtl, mtllib, l, p, ...) does not change the geometry we read.
  });
  if (*result.declared_faces == 0)
    throw Error(file, "no faces ('f' lines): nothing to triangulate");
  return result;
}

// ---- OFF ------------------------------------------------------------------------------------

/// Binary OFF as OpenMesh reads it: little-endian 32-bit counts, vertices of 3 floats (+3 for
/// normals, +2 for texture coordinates), faces of a 32-bit corner count and 32-bit indices.
/// Its face loop does not stop at the end of the file (a truncated file or a huge face count
/// feeds it stale values for ever), so everything must be in the file.
[[nodiscard]] ScanResult scan_binary_off(const std::string& file, std::string_view body,
                                         bool has_normals, bool has_texcoords) {
  if (body.size() < 12) throw Error(file, "binary OFF file truncated: no vertex and face counts");
  const std::uint64_t vertices = read_u32_le(body, 0);
  const std::uint64_t faces = read_u32_le(body, 4);
  check_mesh_counts(file, 0, vertices, faces);
  const std::uint64_t vertex_size = 12 + (has_normals ? 12 : 0) + (has_texcoords ? 8 : 0);
  // Each face takes at least 16 bytes (a count and three indices).
  if (vertices * vertex_size + faces * 16 > body.size() - 12)
    throw Error(file, "binary OFF file truncated or corrupt: " + std::to_string(vertices) +
                          " vertices and " + std::to_string(faces) + " faces do not fit in its " +
                          std::to_string(body.size()) + " bytes (absurd count?)");
  if (faces == 0) throw Error(file, "the file declares no faces");
  std::size_t at = static_cast<std::size_t>(12 + vertices * vertex_size);
  ScanResult result;
  std::vector<std::uint64_t> corners;
  for (std::uint64_t f = 0; f < faces; ++f) {
    if (body.size() - at < 4)
      throw Error(file, "truncated: the file ends in face " + std::to_string(f) + " of " +
                            std::to_string(faces));
    const std::uint64_t n = read_u32_le(body, at);
    at += 4;
    if (n < 3 || n > (body.size() - at) / 4)
      throw Error(file, "face " + std::to_string(f) + " has " + std::to_string(n) +
                            " corners: fewer than 3, or more than the file holds");
    corners.clear();
    for (std::uint64_t k = 0; k < n; ++k, at += 4) {
      const std::uint64_t index = read_u32_le(body, at);
      if (index >= vertices)
        throw Error(file, "face index " + std::to_string(index) +
                              " is out of range: the file has " + std::to_string(vertices) +
                              " vertices (indices start at 0)");
      corners.push_back(index);
    }
    note_face(file, 0, corners, result);
  }
  result.declared_faces = faces;
  return result;
}

/// OFF: header keyword, counts that fit in the file, then numeric finite vertices and faces
/// whose indices are in range. Also rejects what OpenMesh's OFF reader misreads silently.
[[nodiscard]] ScanResult scan_off(const std::string& file, std::string_view text) {
  ScanResult result;
  std::vector<std::string_view> tokens;

  // A cursor over non-blank lines; OpenMesh skips blank lines but not comments.
  std::size_t offset = 0;
  int line_number = 0;
  auto next_line = [&]() -> std::optional<std::string_view> {
    while (offset < text.size()) {
      std::size_t end = text.find('\n', offset);
      if (end == std::string_view::npos) end = text.size();
      std::string_view line = text.substr(offset, end - offset);
      offset = end + 1;
      ++line_number;
      split_tokens(line, tokens);
      if (tokens.empty()) continue;
      if (tokens[0].front() == '#')
        throw Error(file, line_number,
                    "comment lines are not supported in OFF files (OpenMesh's reader reads them "
                    "as data)");
      // A comment after the data on a line is harmless: the reader reads the line's values.
      for (std::size_t i = 1; i < tokens.size(); ++i)
        if (tokens[i].front() == '#') {
          tokens.resize(i);
          break;
        }
      return line;
    }
    return std::nullopt;
  };

  if (!next_line()) throw Error(file, "no 'OFF' header line");
  const std::string_view keyword = tokens[0];
  // [ST][C][N][4][n]OFF, as the OFF specification allows.
  std::string_view prefix = keyword;
  if (prefix.size() < 3 || prefix.substr(prefix.size() - 3) != "OFF")
    throw Error(file, 1,
                "not an OFF file: the first line is " + quote_token(keyword) + ", not 'OFF'");
  prefix.remove_suffix(3);
  const bool has_texcoords = prefix.starts_with("ST");
  if (has_texcoords) prefix.remove_prefix(2);
  const bool has_colors = prefix.starts_with("C");
  if (has_colors) prefix.remove_prefix(1);
  const bool has_normals = prefix.starts_with("N");
  if (has_normals) prefix.remove_prefix(1);
  if (!prefix.empty())
    throw Error(file, line_number,
                "unsupported OFF variant " + quote_token(keyword) + " (only 3D vertices are read)");

  if (tokens.size() > 1 && tokens[1] == "BINARY") {
    if (has_colors)
      throw Error(file, "binary OFF with colours (" + quote_token(keyword) +
                            ") is not supported: its layout depends on reader options");
    return scan_binary_off(file, text.substr(std::min(offset, text.size())), has_normals,
                           has_texcoords);
  }
  if (tokens.size() > 1)
    throw Error(file, line_number,
                "the vertex, face and edge counts must be on the line after " +
                    quote_token(keyword) +
                    " (OpenMesh's reader finds nothing when they share its line)");

  if (!next_line()) throw Error(file, "truncated: no vertex and face counts after the header");
  const int counts_line = line_number;
  // OpenMesh reads three numbers here whatever the line holds: without the edge count it takes
  // the first vertex's x, and every later number lands one place off (a face size then read
  // from a coordinate or a stray -1 asked it for 4 G vertex handles: fuzz-regressions/off/).
  if (tokens.size() < 3)
    throw Error(file, counts_line,
                "expected vertex, face and edge counts, found " + std::to_string(tokens.size()) +
                    " number(s) (the edge count may be 0, but it must be there)");
  const std::optional<std::int64_t> vertex_count = parse_integer(tokens[0]);
  const std::optional<std::int64_t> face_count = parse_integer(tokens[1]);
  if (!vertex_count || !face_count || *vertex_count < 0 || *face_count < 0)
    throw Error(file, counts_line,
                "vertex and face counts " + quote_token(tokens[0]) + " " + quote_token(tokens[1]) +
                    " are not non-negative integers");
  const auto vertices = static_cast<std::uint64_t>(*vertex_count);
  const auto faces = static_cast<std::uint64_t>(*face_count);
  check_mesh_counts(file, counts_line, vertices, faces);
  // Cheapest possible lines: "0 0 0\n" (6 bytes) per vertex, "3 0 1 2\n" (8) per face.
  const std::uint64_t remaining = text.size() - std::min<std::size_t>(offset, text.size());
  if (vertices > remaining || faces > remaining || vertices * 6 + faces * 8 > remaining + 1)
    throw Error(file, counts_line,
                "the header declares " + std::to_string(vertices) + " vertices and " +
                    std::to_string(faces) + " faces, more than the remaining " +
                    std::to_string(remaining) + " bytes can hold (truncated file or absurd count)");
  if (vertices > std::numeric_limits<std::uint32_t>::max())
    throw Error(file, counts_line, "too many vertices for 32-bit indices");

  for (std::uint64_t v = 0; v < vertices; ++v) {
    if (!next_line())
      throw Error(file, "truncated: the header declares " + std::to_string(vertices) +
                            " vertices, the file holds " + std::to_string(v));
    // x y z [nx ny nz] [colour: 1, 3 or 4 values] [u v]
    const std::size_t least =
        3 + (has_normals ? 3 : 0) + (has_colors ? 1 : 0) + (has_texcoords ? 2 : 0);
    if (tokens.size() < least)
      throw Error(file, line_number,
                  "vertex needs " + std::to_string(least) + " values for " + quote_token(keyword) +
                      ", found " + std::to_string(tokens.size()));
    check_numbers(file, line_number, std::span<const std::string_view>(tokens), "vertex");
  }
  std::vector<std::uint64_t> corners;
  for (std::uint64_t f = 0; f < faces; ++f) {
    if (!next_line())
      throw Error(file, "truncated: the header declares " + std::to_string(faces) +
                            " faces, the file holds " + std::to_string(f));
    const std::optional<std::int64_t> n = parse_integer(tokens[0]);
    if (!n)
      throw Error(file, line_number, "face size " + quote_token(tokens[0]) + " is not an integer");
    if (*n < 3)
      throw Error(file, line_number,
                  "face has " + std::to_string(*n) + " vertices, at least 3 needed");
    if (static_cast<std::uint64_t>(*n) > tokens.size() - 1)
      throw Error(file, line_number,
                  "face declares " + std::to_string(*n) + " vertices but lists " +
                      std::to_string(tokens.size() - 1));
    // OpenMesh reads what follows a face's indices (a face colour) only under a 'C' header;
    // otherwise it reads those numbers as the next face (a -1 there asked it for 4 G handles).
    if (!has_colors && static_cast<std::uint64_t>(*n) < tokens.size() - 1)
      throw Error(file, line_number,
                  "numbers after the face's " + std::to_string(*n) +
                      " indices (a face colour?) need a 'COFF' header: without it they would be "
                      "read as the next face");
    corners.clear();
    for (std::size_t k = 1; k <= static_cast<std::size_t>(*n); ++k) {
      const std::optional<std::int64_t> index = parse_integer(tokens[k]);
      if (!index)
        throw Error(file, line_number,
                    "face index " + quote_token(tokens[k]) + " is not an integer");
      if (*index < 0 || static_cast<std::uint64_t>(*index) >= vertices)
        throw Error(file, line_number,
                    "face index " + std::to_string(*index) + " is out of range: the file has " +
                        std::to_string(vertices) + " vertices (indices start at 0)");
      corners.push_back(static_cast<std::uint64_t>(*index));
    }
    note_face(file, line_number, corners, result);
  }
  result.declared_faces = faces;
  if (faces == 0) throw Error(file, counts_line, "the file declares no faces");
  return result;
}

// ---- PLY ------------------------------------------------------------------------------------

struct PlyType {
  std::size_t size = 0;
  bool floating = false;
  bool is_signed = false;
};

struct PlyProperty {
  std::string name;
  bool list = false;
  PlyType count; ///< a list's length type
  PlyType value; ///< the scalar's type, or a list entry's
  /// The face's vertex index list (OpenMesh reads "vertex_indices" or "vertex_index").
  bool indices = false;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

[[nodiscard]] std::optional<PlyType> ply_type(std::string_view type) {
  if (type == "char" || type == "int8") return PlyType{1, false, true};
  if (type == "uchar" || type == "uint8") return PlyType{1, false, false};
  if (type == "short" || type == "int16") return PlyType{2, false, true};
  if (type == "ushort" || type == "uint16") return PlyType{2, false, false};
  if (type == "int" || type == "int32") return PlyType{4, false, true};
  if (type == "uint" || type == "uint32") return PlyType{4, false, false};
  if (type == "float" || type == "float32") return PlyType{4, true, true};
  if (type == "double" || type == "float64") return PlyType{8, true, true};
  return std::nullopt;
}

[[nodiscard]] Error ply_truncated(const std::string& file, const PlyElement& element,
                                  std::uint64_t item) {
  return Error(file, "truncated: the file ends in " + element.name + " " + std::to_string(item) +
                         " of the " + std::to_string(element.count) + " the header declares");
}

/// `line` 0: a binary file, no line to name.
[[nodiscard]] Error ply_index_out_of_range(const std::string& file, int line, std::int64_t index,
                                           std::uint64_t vertices) {
  const std::string message = "face index " + std::to_string(index) +
                              " is out of range: the file has " + std::to_string(vertices) +
                              " vertices (indices start at 0)";
  return line > 0 ? Error(file, line, message) : Error(file, message);
}

[[nodiscard]] std::uint64_t ply_vertex_count(const std::vector<PlyElement>& elements) {
  for (const PlyElement& element : elements)
    if (element.name == "vertex") return element.count;
  return 0;
}

/// The PLY version: "1.0" as the specification writes it, or another spelling of one ("1",
/// "1.00"). Not "nan", "inf" or "1e999", on which OpenMesh's header loop never ends, nor "2.0"
/// or "-1", which it would read as if they were 1.0.
[[nodiscard]] bool is_ply_version_one(std::string_view token) {
  const std::size_t dot = token.find('.');
  const std::string_view whole = token.substr(0, dot);
  const std::string_view fraction =
      dot == std::string_view::npos ? std::string_view() : token.substr(dot + 1);
  const auto digits = [](std::string_view t) {
    return std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  return !whole.empty() && digits(whole) && digits(fraction) &&
         whole.find_first_not_of('0') == whole.size() - 1 && whole.back() == '1' &&
         fraction.find_first_not_of('0') == std::string_view::npos;
}

/// ASCII PLY body, value by value (the format is a token stream, as OpenMesh reads it): every
/// value is a number of its type, vertex values are finite, list lengths are plausible and face
/// indices are in range. OpenMesh's reader desynchronises on "nan", "inf" or a stray word and
/// then reports confusing indices, or none.
void walk_ascii_ply(const std::string& file, std::string_view body, int first_line,
                    const std::vector<PlyElement>& elements, ScanResult& result) {
  std::size_t at = 0;
  int line = first_line;
  auto next_token = [&]() -> std::optional<std::string_view> {
    while (at < body.size() && is_space(body[at])) line += body[at++] == '\n' ? 1 : 0;
    const std::size_t start = at;
    while (at < body.size() && !is_space(body[at])) ++at;
    if (at == start) return std::nullopt;
    return body.substr(start, at - start);
  };
  const std::uint64_t vertices = ply_vertex_count(elements);
  std::vector<std::uint64_t> corners;
  for (const PlyElement& element : elements) {
    const bool is_vertex = element.name == "vertex";
    for (std::uint64_t item = 0; item < element.count; ++item) {
      auto value = [&](const PlyProperty& property, bool floating) -> std::string_view {
        const std::optional<std::string_view> token = next_token();
        if (!token) throw ply_truncated(file, element, item);
        if (floating) {
          const std::optional<double> number = parse_number(*token);
          if (!number)
            throw Error(file, line,
                        element.name + " property '" + property.name + "' value " +
                            quote_token(*token) + " is not a number");
          if (is_vertex && !std::isfinite(*number))
            throw Error(file, line,
                        "vertex has a non-finite value " + quote_token(*token) +
                            " (NaN or Inf) in property '" + property.name + "'");
          // A float beyond its range fails OpenMesh's stream, which then reads the rest shifted.
          if ((is_vertex || property.value.size == 4) && !fits_float(*number))
            throw Error(file, line,
                        element.name + " property '" + property.name + "' value " +
                            quote_token(*token) + " is beyond the float range (Inf as a float)");
        } else if (!parse_integer(*token)) {
          throw Error(file, line,
                      element.name + " property '" + property.name + "' value " +
                          quote_token(*token) + " is not an integer");
        }
        return *token;
      };
      for (const PlyProperty& property : element.properties) {
        if (!property.list) {
          (void)value(property, property.value.floating);
          continue;
        }
        const std::int64_t length = *parse_integer(value(property, false));
        if (length < 0 || static_cast<std::uint64_t>(length) > body.size() - at)
          throw Error(file, line,
                      "list length " + std::to_string(length) + " of " + element.name +
                          " property '" + property.name + "' is impossible here");
        if (property.indices && length < 3)
          throw Error(file, line,
                      "face has " + std::to_string(length) + " vertices, at least 3 needed");
        corners.clear();
        for (std::int64_t k = 0; k < length; ++k) {
          const std::string_view token = value(property, property.value.floating);
          if (!property.indices) continue;
          const std::int64_t index = *parse_integer(token);
          if (index < 0 || static_cast<std::uint64_t>(index) >= vertices)
            throw ply_index_out_of_range(file, line, index, vertices);
          corners.push_back(static_cast<std::uint64_t>(index));
        }
        if (property.indices) note_face(file, line, corners, result);
      }
    }
  }
  // Values left over mean the header does not describe the data (a face with more corners than
  // its count says, say): OpenMesh would read them shifted.
  if (next_token())
    throw Error(file, line,
                "more values than the header declares: the header does not match "
                "the data");
}

/// Binary PLY body: list lengths fit in the file (OpenMesh reads a negative or huge "int" length
/// for ever) and face indices are in range.
void walk_binary_ply(const std::string& file, std::string_view body, bool big_endian,
                     const std::vector<PlyElement>& elements, ScanResult& result) {
  std::size_t at = 0;
  auto read_integer = [&](const PlyType& type) -> std::int64_t {
    std::uint64_t bits = 0;
    for (std::size_t b = 0; b < type.size; ++b) {
      const auto byte = std::uint64_t{static_cast<std::uint8_t>(body[at + b])};
      bits |= byte << (8 * (big_endian ? type.size - 1 - b : b));
    }
    at += type.size;
    if (type.is_signed && type.size < 8 && (bits >> (8 * type.size - 1)) != 0)
      return static_cast<std::int64_t>(bits) - (std::int64_t{1} << (8 * type.size));
    return static_cast<std::int64_t>(bits);
  };
  const std::uint64_t vertices = ply_vertex_count(elements);
  std::vector<std::uint64_t> corners;
  for (const PlyElement& element : elements) {
    const bool fixed = std::none_of(element.properties.begin(), element.properties.end(),
                                    [](const PlyProperty& p) { return p.list; });
    if (fixed) { // the header check already made sure these fit
      std::uint64_t item_size = 0;
      for (const PlyProperty& property : element.properties) item_size += property.value.size;
      at += static_cast<std::size_t>(element.count * item_size);
      continue;
    }
    for (std::uint64_t item = 0; item < element.count; ++item) {
      for (const PlyProperty& property : element.properties) {
        if (!property.list) {
          if (property.value.size > body.size() - at) throw ply_truncated(file, element, item);
          at += property.value.size;
          continue;
        }
        if (property.count.size > body.size() - at) throw ply_truncated(file, element, item);
        const std::int64_t length = read_integer(property.count);
        if (length < 0 ||
            static_cast<std::uint64_t>(length) > (body.size() - at) / property.value.size)
          throw Error(file, "list length " + std::to_string(length) + " in " + element.name + " " +
                                std::to_string(item) + " (property '" + property.name +
                                "') is negative or runs past the end of the file");
        if (!property.indices || property.value.floating) {
          at += static_cast<std::size_t>(length) * property.value.size;
          continue;
        }
        if (length < 3)
          throw Error(file, "face " + std::to_string(item) + " has " + std::to_string(length) +
                                " vertices, at least 3 needed");
        corners.clear();
        for (std::int64_t k = 0; k < length; ++k) {
          const std::int64_t index = read_integer(property.value);
          if (index < 0 || static_cast<std::uint64_t>(index) >= vertices)
            throw ply_index_out_of_range(file, 0, index, vertices);
          corners.push_back(static_cast<std::uint64_t>(index));
        }
        note_face(file, 0, corners, result);
      }
    }
  }
}

/// PLY: a header OpenMesh reads as we do, element counts that fit in the bytes after it, then
/// the body value by value (walk_ascii_ply, walk_binary_ply).
[[nodiscard]] ScanResult scan_ply(const std::string& file, std::string_view bytes) {
  if (!bytes.starts_with("ply"))
    throw Error(file, 1, "not a PLY file: it does not start with 'ply'");
  // The header ends at "end_header" + newline; cap the search so a binary blob is not scanned.
  constexpr std::size_t kMaxHeader = 1 << 20;
  const std::string_view head = bytes.substr(0, kMaxHeader);
  std::size_t header_end = std::string_view::npos;
  std::size_t end_keyword = std::string_view::npos;
  for (std::size_t at = head.find("end_header"); at != std::string_view::npos;
       at = head.find("end_header", at + 1)) {
    if (at != 0 && head[at - 1] != '\n') continue;
    std::size_t after = at + std::strlen("end_header");
    if (after < head.size() && head[after] == '\r') ++after;
    if (after < head.size() && head[after] == '\n') {
      header_end = after + 1;
      end_keyword = at;
      break;
    }
  }
  if (header_end == std::string_view::npos)
    throw Error(file, "truncated PLY header: no 'end_header' line");

  enum class PlyFormat { none, ascii, binary_little, binary_big };
  PlyFormat format = PlyFormat::none;
  std::vector<PlyElement> elements;
  std::vector<std::string_view> tokens;
  int header_lines = 0;
  const auto last_line =
      static_cast<int>(std::count(bytes.begin(), bytes.begin() + std::ptrdiff_t(header_end), '\n'));
  for_each_line(bytes.substr(0, header_end), [&](int line, std::string_view content) {
    header_lines = line;
    split_tokens(content, tokens);
    if (line == 1) {
      if (tokens.size() != 1 || tokens[0] != "ply")
        throw Error(file, 1, "the first line must be 'ply' alone, found " + quote_token(content));
      return;
    }
    if (tokens.empty()) return;
    const std::string_view keyword = tokens[0];
    // OpenMesh reads the header word by word, and a word its stream cannot convert (a version
    // "nan", "inf" or "1e999", a count beyond 32 bits) fails the stream, after which its header
    // loop never ends. Only the format line as the PLY specification writes it, element and
    // property lines of the exact shape, comments and end_header get through.
    if (format == PlyFormat::none) {
      if (keyword != "format" || tokens.size() != 3 || !is_ply_version_one(tokens[2]))
        throw Error(file, line,
                    "expected 'format <ascii|binary_little_endian|binary_big_endian> "
                    "1.0' after 'ply', found " +
                        quote_token(content));
      if (tokens[1] == "ascii")
        format = PlyFormat::ascii;
      else if (tokens[1] == "binary_little_endian")
        format = PlyFormat::binary_little;
      else if (tokens[1] == "binary_big_endian")
        format = PlyFormat::binary_big;
      else
        throw Error(file, line, "unknown PLY format " + quote_token(tokens[1]));
    } else if (keyword == "element") {
      if (tokens.size() != 3)
        throw Error(file, line,
                    "an element line is 'element <name> <count>', found " + quote_token(content));
      // OpenMesh reads counts as 32-bit unsigned; beyond that its header loop never ends.
      const std::optional<std::int64_t> count = parse_integer(tokens[2]);
      if (!count || *count < 0 || *count > std::numeric_limits<std::uint32_t>::max())
        throw Error(file, line,
                    "element count " + quote_token(tokens[2]) +
                        " is not an integer from 0 to 2^32 - 1 (absurd count)");
      for (const PlyElement& element : elements)
        if (element.name == tokens[1])
          throw Error(file, line, "element " + quote_token(tokens[1]) + " declared twice");
      const auto n = static_cast<std::uint64_t>(*count);
      if (tokens[1] == "vertex") check_mesh_counts(file, line, n, 0);
      if (tokens[1] == "face") check_mesh_counts(file, line, 0, n);
      elements.push_back({std::string(tokens[1]), n, {}});
    } else if (keyword == "property") {
      // OpenMesh would write into elements_.back() of an empty list.
      if (elements.empty()) throw Error(file, line, "property before any element");
      const bool list = tokens.size() >= 2 && tokens[1] == "list";
      if (tokens.size() != (list ? 5u : 3u))
        throw Error(file, line,
                    std::string("a property line is ") +
                        (list ? "'property list <count type> <value type> <name>'"
                              : "'property <type> <name>'") +
                        ", found " + quote_token(content));
      const std::optional<PlyType> count = list ? ply_type(tokens[2]) : PlyType{};
      const std::optional<PlyType> value = ply_type(tokens[list ? 3 : 1]);
      if (!count || !value || (list && count->floating))
        throw Error(file, line, "unknown PLY property type in " + quote_token(content));
      const std::string name(tokens[list ? 4 : 2]);
      const bool indices = list && elements.back().name == "face" &&
                           (name == "vertex_indices" || name == "vertex_index");
      elements.back().properties.push_back({name, list, *count, *value, indices});
    } else if (keyword == "format") {
      throw Error(file, line, "a second 'format' line");
    } else if (keyword == "end_header" && line == last_line) {
      return;
    } else if (keyword != "comment") {
      // OpenMesh skips "comment" lines whole, but reads any other line ("obj_info" and stray
      // text, as in assimp's Wuson.ply, included) word by word, each word as a keyword: an
      // "element" there would declare an element we do not know of (with a count it may fail
      // to read, and then loop for ever), an "end_header" would end the header early.
      for (const std::string_view word : tokens)
        if (word == "element" || word == "property" || word == "end_header" || word == "format")
          throw Error(file, line,
                      "unsupported PLY header line " + quote_token(content) +
                          ": OpenMesh would read its '" + std::string(word) + "' as a keyword");
    }
  });
  if (format == PlyFormat::none) throw Error(file, "PLY header has no 'format' line");

  // Least bytes the declared elements need: ASCII writes every value with at least one
  // character and one separator, binary writes each scalar (and list count) at full size.
  constexpr std::uint64_t kSaturated = std::numeric_limits<std::uint64_t>::max();
  const std::uint64_t body = bytes.size() - header_end;
  std::uint64_t least = 0;
  std::string counts;
  bool has_vertices = false;
  ScanResult result;
  for (const PlyElement& element : elements) {
    std::uint64_t per_item = 0;
    for (const PlyProperty& property : element.properties)
      per_item += format == PlyFormat::ascii ? 2
                  : property.list            ? property.count.size
                                             : property.value.size;
    per_item = std::max<std::uint64_t>(per_item, 1);
    counts +=
        (counts.empty() ? "" : " and ") + std::to_string(element.count) + " '" + element.name + "'";
    // Saturating: count <= body keeps each product far below 2^64 (per_item is small), and a
    // count beyond the body saturates at once.
    least =
        element.count > body || least == kSaturated ? kSaturated : least + element.count * per_item;
    has_vertices = has_vertices || element.name == "vertex";
    if (element.name == "face") result.declared_faces = element.count;
  }
  // The last ASCII value needs no separator.
  if (format == PlyFormat::ascii && least > 0 && least != kSaturated) --least;
  if (least > body)
    throw Error(file, "truncated file or absurd count: the header declares " + counts +
                          " elements (" +
                          (least == kSaturated ? std::string("more data than the file holds")
                                               : "at least " + std::to_string(least) + " bytes") +
                          ") but only " + std::to_string(body) + " bytes follow the header");
  if (!has_vertices) throw Error(file, "PLY header declares no 'vertex' element");
  if (!result.declared_faces || *result.declared_faces == 0)
    throw Error(file, "PLY header declares no faces (a point cloud, not a mesh)");
  // What OpenMesh's reader gets right, measured: x, y, z among the vertex scalars; the face's
  // vertex index list first among its properties (it forgets the ones before) and no other list
  // before the end of the face element (it misreads their lengths and shifts what follows).
  bool face_seen = false;
  for (const PlyElement& element : elements) {
    if (face_seen) break;
    if (element.name == "vertex")
      for (const char* axis : {"x", "y", "z"})
        if (std::none_of(element.properties.begin(), element.properties.end(),
                         [&](const PlyProperty& p) { return !p.list && p.name == axis; }))
          throw Error(file, std::string("the 'vertex' element has no '") + axis + "' property");
    if (element.name == "face" &&
        (element.properties.empty() || !element.properties.front().indices))
      throw Error(file, "the 'face' element must start with a 'vertex_indices' list (OpenMesh "
                        "reads no faces otherwise, or misreads them)");
    for (std::size_t i = 0; i < element.properties.size(); ++i) {
      const PlyProperty& property = element.properties[i];
      if (property.list && !(property.indices && i == 0))
        throw Error(file, "unsupported list property '" + property.name + "' in the '" +
                              element.name + "' element: OpenMesh's reader misreads it");
    }
    face_seen = element.name == "face";
  }

  if (format == PlyFormat::ascii) {
    walk_ascii_ply(file, bytes.substr(header_end), header_lines + 1, elements, result);
    return result;
  }
  // OpenMesh finds binary data 12 bytes ("\nend_header\n", or 14 with "\r\n") after the last
  // word before "end_header"; any other whitespace there shifts every value it reads.
  std::size_t last_word = end_keyword;
  while (last_word > 0 && is_space(bytes[last_word - 1])) --last_word;
  const bool crlf = bytes.substr(last_word, 2) == "\r\n";
  if (last_word + (crlf ? 14 : 12) != header_end)
    throw Error(file, "unsupported whitespace around 'end_header': OpenMesh would read the "
                      "binary data from the wrong offset");
  walk_binary_ply(file, bytes.substr(header_end), format == PlyFormat::binary_big, elements,
                  result);
  return result;
}

// ---- STL ------------------------------------------------------------------------------------

/// STL: binary when the size is exactly 84 + 50 * (declared triangles), which is also the rule
/// OpenMesh uses; otherwise it must be ASCII ("solid ...") with complete, numeric facets.
[[nodiscard]] ScanResult scan_stl(const std::string& file, std::string_view bytes) {
  ScanResult result;
  const std::uint64_t size = bytes.size();
  if (size >= 84) {
    const std::uint64_t triangles = read_u32_le(bytes, 80);
    if (84 + 50 * triangles == size) {
      if (triangles == 0) throw Error(file, "binary STL with 0 triangles");
      check_mesh_counts(file, 0, 0, triangles);
      // OpenMesh merges corners through an ordered map, where a NaN key compares equal to
      // anything: the NaN vanishes into some other vertex. Check before it gets there.
      for (std::uint64_t t = 0; t < triangles; ++t)
        for (std::size_t k = 0; k < 9; ++k) {
          const std::size_t at = static_cast<std::size_t>(84 + 50 * t + 12) + 4 * k;
          if (!std::isfinite(std::bit_cast<float>(read_u32_le(bytes, at))))
            throw Error(file, "triangle " + std::to_string(t) +
                                  " has a non-finite vertex coordinate (NaN or Inf)");
        }
      result.declared_faces = triangles;
      return result;
    }
  }
  std::size_t first = 0;
  while (first < bytes.size() && is_space(bytes[first])) ++first;
  if (lower_ascii(bytes.substr(first, 5)) != "solid") {
    if (size < 84)
      throw Error(file, "not an STL file: " + std::to_string(size) +
                            " bytes, too short for a binary STL, and no ASCII 'solid' header");
    const std::uint64_t triangles = read_u32_le(bytes, 80);
    throw Error(file, "truncated or not an STL file: a binary STL declaring " +
                          std::to_string(triangles) + " triangles must be " +
                          std::to_string(84 + 50 * triangles) + " bytes, this file has " +
                          std::to_string(size) + " and no ASCII 'solid' header");
  }
  std::uint64_t facets = 0;
  int corners = -1; // -1: outside a facet
  std::vector<std::string_view> tokens;
  for_each_line(bytes, [&](int line, std::string_view content) {
    split_tokens(content, tokens);
    if (tokens.empty()) return;
    const std::string keyword = lower_ascii(tokens[0]);
    if (keyword == "facet") {
      if (corners >= 0)
        throw Error(file, line, "'facet' inside another facet (missing 'endfacet')");
      corners = 0;
    } else if (keyword == "vertex") {
      if (corners < 0) throw Error(file, line, "'vertex' outside a facet");
      if (tokens.size() != 4) throw Error(file, line, "vertex needs 3 coordinates");
      check_numbers(file, line, std::span<const std::string_view>(tokens).subspan(1), "vertex");
      ++corners;
    } else if (keyword == "endfacet") {
      if (corners != 3)
        throw Error(file, line,
                    "facet has " + std::to_string(std::max(corners, 0)) + " vertices, 3 needed");
      corners = -1;
      check_mesh_counts(file, line, 0, ++facets);
    } else if (keyword != "solid" && keyword != "endsolid" && keyword != "outer" &&
               keyword != "endloop") {
      throw Error(file, line, "unexpected " + quote_token(tokens[0]) + " in an ASCII STL file");
    }
  });
  if (corners >= 0) throw Error(file, "truncated: the last facet has no 'endfacet'");
  if (facets == 0) throw Error(file, "ASCII STL file without facets");
  result.declared_faces = facets;
  return result;
}

// ---- Reading with OpenMesh ------------------------------------------------------------------

/// OpenMesh's log streams (omerr, omlog, omout) and its reader registry are process-wide; loads
/// take turns so one load's messages are not captured by another.
std::mutex& openmesh_mutex() {
  static std::mutex mutex;
  return mutex;
}

/// While alive, points OpenMesh's omerr/omlog/omout at a string instead of the console, so a bad
/// file turns into one Error rather than a page of warnings. It swaps the streams' buffers
/// rather than using mostream::connect/disconnect: disconnect() forgets the target it created in
/// connect() without deleting it (OpenMesh 9), which leaks on every load.
class OpenMeshLogCapture {
public:
  OpenMeshLogCapture() {
    for (std::size_t i = 0; i < kStreams; ++i) {
      stream(i).flush(); // a pending partial line still goes to the console
      previous_[i] = stream(i).rdbuf(&captured_);
    }
  }
  ~OpenMeshLogCapture() {
    for (std::size_t i = 0; i < kStreams; ++i) stream(i).rdbuf(previous_[i]);
  }
  OpenMeshLogCapture(const OpenMeshLogCapture&) = delete;
  OpenMeshLogCapture& operator=(const OpenMeshLogCapture&) = delete;

  /// The distinct lines OpenMesh wrote so far, joined with "; " (at most a few, to stay short).
  [[nodiscard]] std::string messages() const {
    std::vector<std::string> lines;
    std::istringstream in(captured_.text());
    for (std::string line; std::getline(in, line);) {
      while (!line.empty() && is_space(line.back())) line.pop_back();
      for (char& c : line) // readers echo raw file bytes; keep control bytes out of messages
        if (c < ' ' || c > '~') c = '?';
      if (!line.empty() && std::find(lines.begin(), lines.end(), line) == lines.end())
        lines.push_back(line);
    }
    std::string out;
    constexpr std::size_t kMaxLines = 4;
    for (std::size_t i = 0; i < lines.size() && i < kMaxLines; ++i)
      out += (i ? "; " : "") + lines[i];
    if (lines.size() > kMaxLines) out += "; ...";
    return out;
  }

private:
  static constexpr std::size_t kStreams = 3;
  static OpenMesh::mostream& stream(std::size_t i) {
    return i == 0 ? omerr() : i == 1 ? omlog() : omout();
  }

  /// Keeps the first 64 KiB: a reader that loops on a stream error can print without end.
  class BoundedBuffer final : public std::streambuf {
  public:
    [[nodiscard]] const std::string& text() const { return text_; }

  protected:
    int_type overflow(int_type c) override {
      if (!traits_type::eq_int_type(c, traits_type::eof()) && text_.size() < kLimit)
        text_.push_back(traits_type::to_char_type(c));
      return traits_type::not_eof(c);
    }
    std::streamsize xsputn(const char* s, std::streamsize n) override {
      const auto room = static_cast<std::streamsize>(kLimit - std::min(kLimit, text_.size()));
      text_.append(s, static_cast<std::size_t>(std::min(n, room)));
      return n;
    }

  private:
    static constexpr std::size_t kLimit = 64 * 1024;
    std::string text_;
  };

  BoundedBuffer captured_;
  std::array<std::streambuf*, kStreams> previous_{};
};

[[nodiscard]] std::string with_messages(std::string text, const std::string& messages) {
  if (!messages.empty()) text += " (OpenMesh: " + messages + ")";
  return text;
}

/// Receives what OpenMesh's readers parse. Vertices go into the OpenMesh mesh (readers may
/// reach it through kernel()); faces with their per-corner normals and texture coordinates are
/// recorded here as flat lists instead of being linked into the halfedge structure, because
/// ImporterT (OpenMesh 9):
///   - drops faces with out-of-range indices or a repeated vertex, telling only omerr;
///   - moves non-manifold faces onto copied vertices whose normals and texture coordinates stay
///     uninitialised (VectorT's default constructor does not zero them), and assigns such a
///     face's texture coordinates rotated by one corner;
///   - keeps per-corner (OBJ) normals for the first face only when a format sets vertex normals.
/// A ray tracer wants the polygons as written, non-manifold or not, so we keep them all.
class RecordingImporter final : public OpenMesh::IO::ImporterT<OmMesh> {
public:
  struct Corner {
    std::uint32_t vertex = 0;
    std::optional<vec3> normal; ///< OBJ: the normal this corner names
    std::optional<vec2> uv;     ///< the texture coordinate this corner names
  };

  /// `corner_normals`: normals set just before a face belong to that face's corners (OBJ).
  RecordingImporter(OmMesh& mesh, bool corner_normals)
      : ImporterT<OmMesh>(mesh), mesh_(mesh), corner_normals_(corner_normals) {}

  [[nodiscard]] std::size_t face_count() const { return face_start_.size(); }
  [[nodiscard]] std::span<const Corner> face(std::size_t f) const {
    const std::size_t end = f + 1 < face_start_.size() ? face_start_[f + 1] : corners_.size();
    return std::span<const Corner>(corners_).subspan(face_start_[f], end - face_start_[f]);
  }
  /// The first out-of-range vertex index a face used, if any.
  [[nodiscard]] std::optional<std::int64_t> bad_index() const { return bad_index_; }
  [[nodiscard]] std::optional<vec3> vertex_normal(std::uint32_t v) const {
    return v < vertex_normals_.size() ? vertex_normals_[v] : std::nullopt;
  }
  [[nodiscard]] std::optional<vec2> vertex_uv(std::uint32_t v) const {
    return v < vertex_uvs_.size() ? vertex_uvs_[v] : std::nullopt;
  }

  OpenMesh::FaceHandle add_face(const VHandles& indices) override {
    if (indices.size() < 3) return OpenMesh::FaceHandle();
    for (const OpenMesh::VertexHandle vh : indices)
      if (!valid(vh)) {
        if (!bad_index_) bad_index_ = vh.idx();
        return OpenMesh::FaceHandle();
      }
    const OpenMesh::FaceHandle fh(static_cast<int>(face_start_.size()));
    face_start_.push_back(corners_.size());
    for (const OpenMesh::VertexHandle vh : indices) {
      Corner corner;
      corner.vertex = static_cast<std::uint32_t>(vh.idx());
      for (auto it = pending_normals_.rbegin(); it != pending_normals_.rend(); ++it)
        if (it->first == corner.vertex) {
          corner.normal = it->second;
          break;
        }
      corners_.push_back(corner);
    }
    pending_normals_.clear();
    return fh;
  }

  void add_face_texcoords(OpenMesh::FaceHandle fh, OpenMesh::VertexHandle vh,
                          const std::vector<OpenMesh::Vec2f>& uvs) override {
    if (!fh.is_valid() || static_cast<std::size_t>(fh.idx()) >= face_start_.size()) return;
    // As in ImporterT: uvs[0] belongs to the corner at vertex vh, then onwards around the face.
    const std::size_t first = face_start_[static_cast<std::size_t>(fh.idx())];
    const std::size_t n = face(static_cast<std::size_t>(fh.idx())).size();
    std::size_t start = 0;
    while (start < n && static_cast<int>(corners_[first + start].vertex) != vh.idx()) ++start;
    if (start == n) start = 0;
    for (std::size_t i = 0; i < uvs.size() && i < n; ++i)
      corners_[first + (start + i) % n].uv = vec2(uvs[i][0], uvs[i][1]);
  }
  void add_face_texcoords(OpenMesh::FaceHandle fh, OpenMesh::VertexHandle vh,
                          const std::vector<OpenMesh::Vec3f>& uvws) override {
    std::vector<OpenMesh::Vec2f> uvs;
    for (const OpenMesh::Vec3f& t : uvws) uvs.emplace_back(t[0], t[1]);
    add_face_texcoords(fh, vh, uvs);
  }

  void set_normal(OpenMesh::VertexHandle vh, const OpenMesh::Vec3f& n) override {
    if (!valid(vh)) return;
    const vec3 normal(n[0], n[1], n[2]);
    set_at(vertex_normals_, vh, normal);
    if (corner_normals_)
      pending_normals_.emplace_back(static_cast<std::uint32_t>(vh.idx()), normal);
  }
  void set_normal(OpenMesh::VertexHandle vh, const OpenMesh::Vec3d& n) override {
    set_normal(vh, OpenMesh::Vec3f(static_cast<float>(n[0]), static_cast<float>(n[1]),
                                   static_cast<float>(n[2])));
  }
  void set_texcoord(OpenMesh::VertexHandle vh, const OpenMesh::Vec2f& t) override {
    if (valid(vh)) set_at(vertex_uvs_, vh, vec2(t[0], t[1]));
  }
  void set_texcoord(OpenMesh::VertexHandle vh, const OpenMesh::Vec3f& t) override {
    if (valid(vh)) set_at(vertex_uvs_, vh, vec2(t[0], t[1]));
  }

  // Our face handles name recorded faces, not faces of the mesh: nothing may reach the mesh's
  // face or halfedge properties with them. Face normals, colours and status are not used.
  void set_texcoord(OpenMesh::HalfedgeHandle, const OpenMesh::Vec2f&) override {}
  void set_texcoord(OpenMesh::HalfedgeHandle, const OpenMesh::Vec3f&) override {}
  void set_normal(OpenMesh::FaceHandle, const OpenMesh::Vec3f&) override {}
  void set_normal(OpenMesh::FaceHandle, const OpenMesh::Vec3d&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec3f&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec4f&) override {}
  void set_status(OpenMesh::FaceHandle, const OpenMesh::Attributes::StatusInfo&) override {}
  void set_face_texindex(OpenMesh::FaceHandle, int) override {}
  [[nodiscard]] std::size_t n_faces() const override { return face_start_.size(); }

private:
  [[nodiscard]] bool valid(OpenMesh::VertexHandle vh) const {
    return vh.idx() >= 0 && static_cast<std::size_t>(vh.idx()) < mesh_.n_vertices();
  }
  template <class T>
  static void set_at(std::vector<std::optional<T>>& values, OpenMesh::VertexHandle vh, const T& v) {
    const auto i = static_cast<std::size_t>(vh.idx());
    if (values.size() <= i) values.resize(i + 1);
    values[i] = v;
  }

  OmMesh& mesh_;
  bool corner_normals_;
  std::vector<std::size_t> face_start_;
  std::vector<Corner> corners_;
  std::vector<std::pair<std::uint32_t, vec3>> pending_normals_;
  std::vector<std::optional<vec3>> vertex_normals_;
  std::vector<std::optional<vec2>> vertex_uvs_;
  std::optional<std::int64_t> bad_index_;
};

/// The triangle mesh of what the importer recorded: polygons become fans; triangles that repeat
/// a vertex are dropped (no area, no meaning); output vertices are file vertices split where
/// corners disagree on normal or texture coordinate (OBJ seams). Corners without a normal get
/// the smooth normal of their file vertex. Texture coordinates are kept only when every corner
/// has one: a mesh cannot be partly textured.
[[nodiscard]] TriangleMesh to_triangle_mesh(const OmMesh& om, const RecordingImporter& in) {
  using Corner = RecordingImporter::Corner;
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

  TriangleMesh welded; // over the file's vertices, for smooth normals
  welded.positions.reserve(om.n_vertices());
  for (const auto vh : om.vertices()) {
    const auto& p = om.point(vh);
    welded.positions.emplace_back(p[0], p[1], p[2]);
  }
  bool has_uvs = in.face_count() > 0;
  for (std::size_t f = 0; f < in.face_count(); ++f) {
    const std::span<const Corner> corners = in.face(f);
    for (std::size_t k = 1; k + 1 < corners.size(); ++k) {
      const uvec3 t(corners[0].vertex, corners[k].vertex, corners[k + 1].vertex);
      if (t.x != t.y && t.y != t.z && t.x != t.z) welded.triangles.push_back(t);
    }
    for (const Corner& c : corners) has_uvs = has_uvs && (c.uv || in.vertex_uv(c.vertex));
  }
  welded.compute_vertex_normals();

  TriangleMesh mesh;
  std::vector<std::uint32_t> first_output(om.n_vertices(), kNone); // per file vertex
  std::vector<std::uint32_t> next_output;                          // chain of its splits
  auto output_vertex = [&](const Corner& c) {
    std::optional<vec3> normal = c.normal ? c.normal : in.vertex_normal(c.vertex);
    if (normal && glm::dot(*normal, *normal) > 0.0f)
      *normal = glm::normalize(*normal); // NaN stays NaN, for validate() to report
    else
      normal = welded.normals[c.vertex]; // none, or zero length: the file gives no direction
    const vec2 uv = has_uvs ? (c.uv ? *c.uv : *in.vertex_uv(c.vertex)) : vec2(0.0f);
    for (std::uint32_t i = first_output[c.vertex]; i != kNone; i = next_output[i])
      if ((!has_uvs || mesh.uvs[i] == uv) && mesh.normals[i] == *normal) return i;
    const auto index = static_cast<std::uint32_t>(mesh.positions.size());
    mesh.positions.push_back(welded.positions[c.vertex]);
    mesh.normals.push_back(*normal);
    if (has_uvs) mesh.uvs.push_back(uv);
    next_output.push_back(first_output[c.vertex]);
    first_output[c.vertex] = index;
    return index;
  };
  for (std::size_t f = 0; f < in.face_count(); ++f) {
    const std::span<const Corner> corners = in.face(f);
    for (std::size_t k = 1; k + 1 < corners.size(); ++k) {
      const Corner& a = corners[0];
      const Corner& b = corners[k];
      const Corner& c = corners[k + 1];
      if (a.vertex == b.vertex || b.vertex == c.vertex || a.vertex == c.vertex) continue;
      // One statement each: output vertices are numbered in corner order, not in whatever
      // order the compiler evaluates arguments.
      const std::uint32_t ia = output_vertex(a);
      const std::uint32_t ib = output_vertex(b);
      const std::uint32_t ic = output_vertex(c);
      mesh.triangles.emplace_back(ia, ib, ic);
    }
  }
  return mesh;
}

} // namespace

bool is_mesh_file_extension(std::string_view extension) { return format_of(extension).has_value(); }

TriangleMesh load_mesh_file(const fs::path& path) {
  const std::string file = path.string();
  // Regular files only (a device or FIFO would be read for ever), within the size bound; then
  // the extension, then the bytes.
  (void)check_regular_file(path, kMaxDataFileBytes, "mesh file");
  const std::optional<MeshFormat> format = format_of(path.extension().string());
  if (!format)
    throw Error(file, "unknown mesh file extension " + quote_token(path.extension().string()) +
                          " (expected .obj, .ply, .off or .stl)");
  const std::string bytes = read_file_bounded(path, kMaxDataFileBytes, "mesh file");
  if (bytes.empty()) throw Error(file, "empty file (0 bytes)");
  ScanResult scan;
  switch (*format) {
  case MeshFormat::obj:
    scan = scan_obj(file, bytes);
    break;
  case MeshFormat::off:
    scan = scan_off(file, bytes);
    break;
  case MeshFormat::ply:
    scan = scan_ply(file, bytes);
    break;
  case MeshFormat::stl:
    scan = scan_stl(file, bytes);
    break;
  }

  OpenMesh::IO::Options options = OpenMesh::IO::Options::VertexNormal |
                                  OpenMesh::IO::Options::VertexTexCoord |
                                  OpenMesh::IO::Options::FaceTexCoord;
  // Only positions live in the OpenMesh mesh; the importer keeps the rest (see above). Some
  // readers (OFF) only pass normals and texture coordinates on when the mesh has the properties.
  OmMesh om;
  om.request_vertex_normals();
  om.request_vertex_texcoords2D();
  RecordingImporter importer(om, *format == MeshFormat::obj);
  std::string messages;
  {
    const std::lock_guard lock(openmesh_mutex());
    OpenMeshLogCapture capture;
    bool ok = false;
    try {
      // By file name, not from a stream over `bytes`: the OFF reader takes the header's
      // variant (NOFF, STOFF, BINARY) from can_u_read(filename), and from a stream it would
      // use whatever the previous file had.
      ok = OpenMesh::IO::IOManager().read(file, importer, options);
    } catch (const std::exception& e) {
      throw Error(file, with_messages(std::string("OpenMesh failed to read the file: ") + e.what(),
                                      capture.messages()));
    }
    messages = capture.messages();
    if (!ok)
      throw Error(
          file, with_messages("malformed or truncated file: OpenMesh could not read it", messages));
  }

  if (const std::optional<std::int64_t> bad = importer.bad_index())
    throw Error(file, "a face refers to vertex index " + std::to_string(*bad) +
                          ", out of range: the file has " + std::to_string(om.n_vertices()) +
                          " vertices");
  const std::uint64_t faces = importer.face_count();
  // OpenMesh's readers skip some faces on their own (OBJ: repeated vertices; STL: facets whose
  // corners coincide); anything else missing means the reader lost its way in the file.
  if (scan.declared_faces && *format != MeshFormat::stl &&
      faces + scan.faces_with_repeated_vertex < *scan.declared_faces)
    throw Error(file,
                with_messages("malformed file: OpenMesh read only " + std::to_string(faces) +
                                  " of the " + std::to_string(*scan.declared_faces) + " faces",
                              messages));
  if (faces == 0) throw Error(file, with_messages("the file contains no faces", messages));

  TriangleMesh mesh = to_triangle_mesh(om, importer);
  if (mesh.triangles.empty())
    throw Error(file, "all " + std::to_string(faces) +
                          " faces are degenerate (they repeat a vertex): no triangles");
  mesh.validate(file);

  const bool all_degenerate =
      std::all_of(mesh.triangles.begin(), mesh.triangles.end(), [&](const uvec3& t) {
        const vec3 n = glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                                  mesh.positions[t.z] - mesh.positions[t.x]);
        return !(glm::dot(n, n) > 0.0f);
      });
  if (all_degenerate)
    throw Error(file, "all " + std::to_string(mesh.triangle_count()) +
                          " triangles are degenerate (zero area)");
  return mesh;
}

} // namespace specula
