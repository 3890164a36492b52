#include "specula/image/image_io.h"

#include "specula/core/error.h"
#include "specula/core/file_io.h"
#include "specula/core/memory_budget.h"
#include "specula/image/srgb.h"

// The implementations live in the system libstb; only the declarations are included here.
#include <stb_image.h>
#include <stb_image_write.h>

#include <Iex.h>
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfPartType.h>
#include <ImfTileDescription.h>
#include <ImfVersion.h>
#include <openexr.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <initializer_list>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace specula {

namespace {

using Bytes = std::vector<std::uint8_t>;

[[noreturn]] void fail(const std::filesystem::path& path, const std::string& message) {
  throw Error(path.string(), message);
}

std::string errno_message() { return std::error_code(errno, std::generic_category()).message(); }

std::string size_text(std::int64_t width, std::int64_t height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

/// The whole file, with the reasons a file cannot be read told apart (a missing file and an
/// empty one are different mistakes for the user): regular files only, within
/// kMaxDataFileBytes (docs/limits.md), so a device or FIFO named .png or .exr is refused.
std::string read_file_bytes(const std::filesystem::path& path, std::string_view what) {
  std::string bytes = read_file_bounded(path, kMaxDataFileBytes, what);
  if (bytes.empty()) fail(path, "empty file");
  return bytes;
}

std::span<const std::uint8_t> as_bytes(const std::string& bytes) {
  return {reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()};
}

std::string lowercase_extension(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

// --- PNG ---------------------------------------------------------------------------------------

constexpr std::array<std::uint8_t, 8> kPngSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};

/// Owns memory returned by stb_image.
struct StbiFree {
  void operator()(void* p) const noexcept { stbi_image_free(p); }
};

std::string stbi_reason() {
  const char* reason = stbi_failure_reason();
  return reason != nullptr ? reason : "unknown reason";
}

// --- OpenEXR ----------------------------------------------------------------------------------
// Through the OpenEXR library (Debian's libopenexr 3.1). Files are read into memory first, so a
// missing or empty file gets the same messages as a PNG, and the library reads from a
// bounds-checked stream. In order: the header's attribute framing is walked (declared sizes
// within the file, channels sorted), the header alone is read and checked (required attributes
// present, data window within kMaxFramebufferSide, R, G, B or Y present and not subsampled),
// every chunk is decoded once by OpenEXRCore, and only then does Imf::InputFile read the pixels.
// Each step answers a way OpenEXR 3.1 misbehaves on bad input: docs/design/openexr-quirks.md.

/// An Imf::IStream over bytes in memory. Reading past the end throws, as the library expects.
class ExrMemoryInput final : public Imf::IStream {
public:
  ExrMemoryInput(std::span<const std::uint8_t> bytes, const std::string& name)
      : Imf::IStream(name.c_str()), bytes_(bytes) {}

  bool read(char c[], int n) override {
    if (n < 0 || position_ > bytes_.size() ||
        static_cast<std::uint64_t>(n) > bytes_.size() - position_) {
      throw Iex::InputExc("unexpected end of file");
    }
    std::memcpy(c, bytes_.data() + position_, static_cast<std::size_t>(n));
    position_ += static_cast<std::uint64_t>(n);
    return position_ < bytes_.size();
  }
  std::uint64_t tellg() override { return position_; }
  void seekg(std::uint64_t position) override { position_ = position; }

private:
  std::span<const std::uint8_t> bytes_;
  std::uint64_t position_ = 0;
};

std::uint32_t le32(std::span<const std::uint8_t> bytes, std::size_t at) {
  return std::uint32_t{bytes[at]} | std::uint32_t{bytes[at + 1]} << 8 |
         std::uint32_t{bytes[at + 2]} << 16 | std::uint32_t{bytes[at + 3]} << 24;
}

/// The layout requires the channel list sorted by name. The C++ library sorts the list it reads,
/// so samples stored in another order would silently land in the wrong channels, and
/// OpenEXRCore 3.1 crashes (a NULL write in exr_decoding_run) on some such files. `list` is the
/// value of the chlist attribute: entries of a null-terminated name and 16 bytes, then a 0.
/// The library reads entries until the empty name, whatever size the attribute declares, so
/// the list must end exactly at its declared end: otherwise the library's reading and the
/// framing walked here part ways, and the library takes the bytes after the list for the next
/// attribute (a fuzzer finding: a 379-byte file whose desynchronised header asked for 1.8 GB).
void check_exr_channel_list(std::span<const std::uint8_t> list, const std::filesystem::path& path) {
  std::optional<std::string_view> previous;
  std::size_t at = 0;
  while (at < list.size() && list[at] != 0) {
    const auto end = std::find(list.begin() + static_cast<std::ptrdiff_t>(at), list.end(), 0);
    if (end == list.end()) break; // a name running past the value: refused below
    const std::string_view name(reinterpret_cast<const char*>(list.data()) + at,
                                static_cast<std::size_t>(end - list.begin()) - at);
    if (previous && name <= *previous) { // char_traits order: bytes as unsigned, as strcmp
      fail(path, "corrupt EXR: channel list not sorted by name ('" + printable(*previous, 64) +
                     "' before '" + printable(name, 64) + "')");
    }
    previous = name;
    at += name.size() + 1 + 16; // pixel type, pLinear, reserved, x and y sampling
  }
  if (at + 1 != list.size() || list[at] != 0) {
    fail(path, "corrupt EXR: the channel list does not end at its declared size of " +
                   std::to_string(list.size()) + " bytes");
  }
}

/// The size the library reads for a value of `type` whatever the declared size says, for the
/// fixed-size types of OpenEXR 3.1 (ImfStandardAttributes and the typed attributes).
std::optional<std::uint32_t> exr_fixed_value_size(std::string_view type) {
  static constexpr std::array<std::pair<std::string_view, std::uint32_t>, 25> kSizes = {{
      {"box2i", 16}, {"box2f", 16}, {"chromaticities", 32}, {"compression", 1},
      {"deepImageState", 1}, {"double", 8}, {"envmap", 1}, {"float", 4}, {"int", 4},
      {"keycode", 28}, {"lineOrder", 1}, {"m33f", 36}, {"m33d", 72}, {"m44f", 64},
      {"m44d", 128}, {"rational", 8}, {"tiledesc", 9}, {"timecode", 8}, {"v2i", 8}, {"v2f", 8},
      {"v2d", 16}, {"v3i", 12}, {"v3f", 12}, {"v3d", 24}, {"uchar", 1},
  }};
  for (const auto& [name, size] : kSizes) {
    if (name == type) return size;
  }
  return std::nullopt;
}

/// An attribute value must be read by the library exactly as its declared size frames it, and
/// must not make the library allocate more than the value holds: types read at a fixed size
/// must declare that size, a string vector's strings and a preview's pixels must fill the value.
void check_exr_attribute_value(std::string_view name, std::string_view type,
                               std::span<const std::uint8_t> value,
                               const std::filesystem::path& path) {
  const auto corrupt = [&](const std::string& what) {
    fail(path, "corrupt EXR: header attribute '" + printable(name, 64) + "' of type '" +
                   printable(type, 64) + "' " + what);
  };
  if (const auto fixed = exr_fixed_value_size(type)) {
    if (value.size() != *fixed) {
      corrupt("declares " + std::to_string(value.size()) + " bytes; the type has " +
              std::to_string(*fixed));
    }
  } else if (type == "chlist") {
    check_exr_channel_list(value, path);
  } else if (type == "floatvector") {
    if (value.size() % 4 != 0) corrupt("has a size that is not a multiple of 4");
  } else if (type == "stringvector") {
    // Each string: a 32-bit length, then that many bytes; the library sizes each string from its
    // length before reading it.
    for (std::size_t at = 0; at < value.size();) {
      if (value.size() - at < 4) corrupt("ends inside a string length");
      const std::uint32_t length = le32(value, at);
      at += 4;
      if (length > value.size() - at) corrupt("has a string longer than the attribute");
      at += length;
    }
  } else if (type == "preview") {
    // Width and height, then width × height RGBA bytes, allocated from the two numbers.
    if (value.size() < 8) corrupt("is shorter than its width and height");
    const std::uint64_t pixels = std::uint64_t{le32(value, 0)} * le32(value, 4);
    if (8 + 4 * pixels != value.size()) corrupt("does not hold the pixels its size names");
  }
}

/// The names of the header's attributes, from their framing (name, type, size), with each value
/// checked against how the library will read it (check_exr_attribute_value; reporting a header
/// that ends early is left to the library). Header::readFrom allocates an attribute's declared
/// size before reading its value (and zero-fills it, for strings), so a 200-byte file declaring
/// a 2 GiB string would cost 2 GiB: every declared size must fit in the rest of the file.
std::vector<std::string> exr_attribute_names(std::span<const std::uint8_t> bytes,
                                             const std::filesystem::path& path) {
  std::vector<std::string> names;
  std::size_t at = 8; // after the magic number and version field
  const auto next_text = [&]() -> std::optional<std::string_view> {
    const auto end = std::find(bytes.begin() + static_cast<std::ptrdiff_t>(at), bytes.end(), 0);
    if (end == bytes.end()) return std::nullopt;
    const std::string_view text(reinterpret_cast<const char*>(bytes.data()) + at,
                                static_cast<std::size_t>(end - bytes.begin()) - at);
    at += text.size() + 1;
    return text;
  };
  for (;;) {
    const auto name = next_text();
    if (!name || name->empty()) return names;
    const auto type = next_text();
    if (!type || bytes.size() - at < 4) return names;
    const std::uint32_t size = le32(bytes, at);
    at += 4;
    if (size > bytes.size() - at) {
      fail(path, "truncated or corrupt EXR: header attribute '" + printable(*name, 64) +
                     "' declares " + std::to_string(size) + " bytes, more than the " +
                     std::to_string(bytes.size() - at) + " left in the file");
    }
    check_exr_attribute_value(*name, *type, bytes.subspan(at, size), path);
    at += size;
    names.emplace_back(*name);
  }
}

/// Which channels become R, G and B: the file's R, G, B, or its Y three times for a
/// luminance-only image.
struct ExrColourChannels {
  std::array<std::string, 3> names;
  bool gray = false;
};

/// The checks made on the header alone, before Imf::InputFile allocates line or tile tables
/// sized by it. Returns the channels to read.
ExrColourChannels check_exr_header(const Imf::Header& header,
                                   const std::vector<std::string>& attributes, bool tiled,
                                   const std::filesystem::path& path) {
  // Imf::Header starts with default values for these (and checks that the file's have the same
  // types), so whether the file has them is seen in its own list: a missing one must not be
  // silently replaced (by a default 64x64 data window, say).
  for (const char* name : {"channels", "compression", "dataWindow", "displayWindow", "lineOrder",
                           "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth"}) {
    if (std::find(attributes.begin(), attributes.end(), name) == attributes.end()) {
      fail(path, std::string("corrupt EXR: header has no ") + name + " attribute");
    }
  }
  if (tiled && !header.hasTileDescription()) {
    fail(path, "corrupt EXR: tiled file without a tiles attribute");
  }
  if (header.hasType() && Imf::isDeepData(header.type())) fail(path, "unsupported EXR: deep data");

  // Sizes in 64 bits: a forged window of ±2^31 must not overflow before it is rejected.
  const Imath::Box2i& window = header.dataWindow();
  const std::int64_t width = std::int64_t{window.max.x} - window.min.x + 1;
  const std::int64_t height = std::int64_t{window.max.y} - window.min.y + 1;
  if (width < 1 || height < 1) {
    fail(path, "corrupt EXR: empty data window (" + size_text(width, height) + ")");
  }
  if (width > kMaxFramebufferSide || height > kMaxFramebufferSide) {
    fail(path, "EXR size " + size_text(width, height) + " is outside [1, " +
                   std::to_string(kMaxFramebufferSide) + "] per side");
  }
  header.sanityCheck(tiled); // the library's own checks: windows, modes, compression, ...

  const Imf::ChannelList& channels = header.channels();
  ExrColourChannels colour;
  if (channels.findChannel("R") != nullptr && channels.findChannel("G") != nullptr &&
      channels.findChannel("B") != nullptr) {
    colour.names = {"R", "G", "B"};
  } else if (channels.findChannel("Y") != nullptr && channels.findChannel("RY") == nullptr &&
             channels.findChannel("BY") == nullptr) {
    colour.names = {"Y", "Y", "Y"};
    colour.gray = true;
  } else {
    std::string found;
    for (auto it = channels.begin(); it != channels.end(); ++it)
      found += " " + printable(it.name(), 64);
    fail(path, "unsupported EXR: no R, G, B channels (nor Y alone); found:" +
                   (found.empty() ? std::string(" none") : found));
  }
  for (const std::string& name : colour.names) {
    const Imf::Channel& channel = *channels.findChannel(name);
    if (channel.xSampling != 1 || channel.ySampling != 1) {
      fail(path, "unsupported EXR: channel " + name + " is subsampled (" +
                     size_text(channel.xSampling, channel.ySampling) + ")");
    }
  }
  return colour;
}

// --- Chunk check through OpenEXRCore ---------------------------------------------------------
// The C++ library (3.1) does not check that a chunk decompresses to the size the header implies:
// a corrupt file whose data window or tile size no longer matches its chunks (one flipped byte
// suffices) reads "successfully", its missing samples copied from uninitialised memory. The C
// library of the same package, OpenEXRCore, written for fuzzed input, checks every chunk's
// framing and decompressed size; it decodes each chunk here into a scratch buffer, which is
// discarded. Core 3.1 has no DWAA/DWAB decoder, so chunks of those are checked for framing only.

/// Where OpenEXRCore reads from, and the first error it reported.
struct ExrCoreInput {
  std::span<const std::uint8_t> bytes;
  std::string error;
};

std::int64_t exr_core_read(exr_const_context_t, void* user, void* buffer, std::uint64_t size,
                           std::uint64_t offset, exr_stream_error_func_ptr_t) {
  const auto bytes = static_cast<ExrCoreInput*>(user)->bytes;
  if (offset >= bytes.size()) return 0;
  const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(size, bytes.size() - offset));
  std::memcpy(buffer, bytes.data() + offset, n);
  return static_cast<std::int64_t>(n);
}

std::int64_t exr_core_size(exr_const_context_t, void* user) {
  return static_cast<std::int64_t>(static_cast<ExrCoreInput*>(user)->bytes.size());
}

/// Keeps the first message (the cause; later ones report the failed step), prints nothing.
void exr_core_error(exr_const_context_t context, exr_result_t, const char* message) {
  void* user = nullptr;
  if (exr_get_user_data(context, &user) != EXR_ERR_SUCCESS || user == nullptr) return;
  auto& input = *static_cast<ExrCoreInput*>(user);
  if (input.error.empty() && message != nullptr) input.error = one_line(message);
}

/// Owns an OpenEXRCore read context.
struct ExrCoreContext {
  exr_context_t context = nullptr;
  ExrCoreContext() = default;
  ExrCoreContext(const ExrCoreContext&) = delete;
  ExrCoreContext& operator=(const ExrCoreContext&) = delete;
  ~ExrCoreContext() {
    if (context != nullptr) exr_finish(&context);
  }
};

/// Owns the buffers of one chunk's decode pipeline.
struct ExrCoreDecode {
  exr_const_context_t context;
  // Value-initialised: all zero, what EXR_DECODE_PIPELINE_INITIALIZER ({0}) means, without
  // Clang's -Wmissing-field-initializers on the macro.
  exr_decode_pipeline_t decode{};
  explicit ExrCoreDecode(exr_const_context_t c) : context(c) {}
  ExrCoreDecode(const ExrCoreDecode&) = delete;
  ExrCoreDecode& operator=(const ExrCoreDecode&) = delete;
  ~ExrCoreDecode() { exr_decoding_destroy(context, &decode); }
};

void check_exr_chunks(std::span<const std::uint8_t> bytes, const std::filesystem::path& path) {
  ExrCoreInput input{bytes, {}};
  const auto check = [&](exr_result_t result) {
    if (result == EXR_ERR_SUCCESS) return;
    fail(path,
         "corrupt EXR: " + (input.error.empty() ? std::string(exr_get_default_error_message(result))
                                                : input.error));
  };
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.user_data = &input;
  init.read_fn = &exr_core_read;
  init.size_fn = &exr_core_size;
  init.error_handler_fn = &exr_core_error;
  init.max_image_width = static_cast<int>(kMaxFramebufferSide);
  init.max_image_height = static_cast<int>(kMaxFramebufferSide);
  init.max_tile_width = static_cast<int>(kMaxFramebufferSide);
  init.max_tile_height = static_cast<int>(kMaxFramebufferSide);
  init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION; // a broken offset table is an error
  ExrCoreContext owner;
  check(exr_start_read(&owner.context, path.string().c_str(), &init));
  const exr_const_context_t context = owner.context;

  exr_attr_box2i_t window{};
  exr_storage_t storage = EXR_STORAGE_SCANLINE;
  exr_compression_t compression = EXR_COMPRESSION_NONE;
  check(exr_get_data_window(context, 0, &window));
  check(exr_get_storage(context, 0, &storage));
  check(exr_get_compression(context, 0, &compression));
  // Core reads the header itself; it must agree with the C++ reader's, already checked.
  const std::int64_t width = std::int64_t{window.max.x} - window.min.x + 1;
  const std::int64_t height = std::int64_t{window.max.y} - window.min.y + 1;
  if (width < 1 || height < 1 || width > kMaxFramebufferSide || height > kMaxFramebufferSide ||
      (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED)) {
    fail(path, "corrupt EXR: inconsistent header");
  }

  // Every chunk of the image (level 0 for tiles): its table entry and framing first.
  std::vector<exr_chunk_info_t> chunks;
  if (storage == EXR_STORAGE_SCANLINE) {
    std::int32_t lines = 0;
    check(exr_get_scanlines_per_chunk(context, 0, &lines));
    if (lines < 1) fail(path, "corrupt EXR: inconsistent header");
    for (std::int64_t y = window.min.y; y <= window.max.y; y += lines) {
      check(exr_read_scanline_chunk_info(context, 0, static_cast<int>(y), &chunks.emplace_back()));
    }
  } else {
    std::int32_t tile_width = 0;
    std::int32_t tile_height = 0;
    check(exr_get_tile_sizes(context, 0, 0, 0, &tile_width, &tile_height));
    if (tile_width < 1 || tile_height < 1) fail(path, "corrupt EXR: inconsistent header");
    for (std::int64_t ty = 0; ty < (height + tile_height - 1) / tile_height; ++ty) {
      for (std::int64_t tx = 0; tx < (width + tile_width - 1) / tile_width; ++tx) {
        check(exr_read_tile_chunk_info(context, 0, static_cast<int>(tx), static_cast<int>(ty), 0, 0,
                                       &chunks.emplace_back()));
      }
    }
  }
  if (compression == EXR_COMPRESSION_DWAA || compression == EXR_COMPRESSION_DWAB) return;

  // Then each chunk decoded: every channel, read or not, into its own float plane of a scratch
  // buffer. Leaving the unread channels without a destination (as Core allows) is not safe in
  // 3.1: its fast unpackers for 3 and 4 interleaved HALF channels are chosen from the filled
  // channels alone and then write every channel, a luminance file's Y beside two unread ones
  // to null.
  std::vector<float> scratch;
  for (const exr_chunk_info_t& chunk : chunks) {
    ExrCoreDecode pipeline{context};
    exr_decode_pipeline_t& decode = pipeline.decode;
    check(exr_decoding_initialize(context, 0, &chunk, &decode));
    std::size_t samples = 0;
    for (int c = 0; c < decode.channel_count; ++c) {
      const exr_coding_channel_info_t& channel = decode.channels[c];
      if (channel.width < 0 || channel.height < 0) fail(path, "corrupt EXR: inconsistent chunk");
      samples += static_cast<std::size_t>(channel.width) * static_cast<std::size_t>(channel.height);
    }
    // At most twice the chunk's decompressed size (2-byte HALF samples become floats), the
    // buffer Core allocates for the same chunk in exr_decoding_run. Neither is checked against
    // the memory budget, which only the framebuffer is: a chunk grows with the channel count.
    scratch.assign(std::max<std::size_t>(samples, 1), 0.0f);
    std::size_t at = 0;
    for (int c = 0; c < decode.channel_count; ++c) {
      exr_coding_channel_info_t& channel = decode.channels[c];
      channel.decode_to_ptr = reinterpret_cast<std::uint8_t*>(scratch.data() + at);
      channel.user_pixel_stride = sizeof(float);
      channel.user_line_stride = static_cast<std::int32_t>(sizeof(float)) * channel.width;
      channel.user_bytes_per_element = sizeof(float);
      channel.user_data_type = EXR_PIXEL_FLOAT;
      at += static_cast<std::size_t>(channel.width) * static_cast<std::size_t>(channel.height);
    }
    check(exr_decoding_choose_default_routines(context, 0, &decode));
    check(exr_decoding_run(context, 0, &decode));
  }
}

Framebuffer decode_exr(std::span<const std::uint8_t> bytes, const std::filesystem::path& path) {
  // Version field: the low byte is the format version, the rest are feature flags.
  if (bytes.size() < 8) fail(path, "truncated EXR: file ends inside the version field");
  const auto version = static_cast<int>(le32(bytes, 4));
  if (Imf::isMultiPart(version)) {
    fail(path, "unsupported EXR: multi-part file (only single-part images are read)");
  }
  if (Imf::isNonImage(version)) fail(path, "unsupported EXR: deep data");
  if (Imf::getVersion(version) != Imf::EXR_VERSION) {
    fail(path, "unsupported EXR: format version " + std::to_string(Imf::getVersion(version)));
  }
  if (!Imf::supportsFlags(Imf::getFlags(version))) {
    fail(path, "unsupported EXR: unknown version flags " +
                   std::to_string(static_cast<std::uint32_t>(Imf::getFlags(version)) >> 8));
  }
  const bool tiled = Imf::isTiled(version);
  const std::vector<std::string> attributes = exr_attribute_names(bytes, path);

  // The header alone first, into a default Imf::Header: its predefined attributes make readFrom
  // refuse a file attribute of the same name and another type. (Erasing them instead lets an
  // attribute "channels" of an unknown type in, on which Header::sanityCheck crashes.)
  ExrMemoryInput stream(bytes, path.string());
  Imf::Header header;
  stream.seekg(8);
  int header_version = version;
  header.readFrom(stream, header_version);
  const ExrColourChannels colour = check_exr_header(header, attributes, tiled, path);
  {
    // The framebuffer the pixels go to, allocated once the chunks passed: known now.
    const Imath::Box2i& window = header.dataWindow();
    const auto w = static_cast<std::uint64_t>(std::int64_t{window.max.x} - window.min.x + 1);
    const auto h = static_cast<std::uint64_t>(std::int64_t{window.max.y} - window.min.y + 1);
    check_memory(w * h * sizeof(vec3), memory_budget({}, "--memory-limit"), path.string(),
                 "reading this " + size_text(std::int64_t(w), std::int64_t(h)) + " EXR");
  }
  check_exr_chunks(bytes, path);

  // The header passed: now the library reads the file from the start, tables and pixels.
  stream.seekg(0);
  Imf::InputFile file(stream);
  const Imath::Box2i window = header.dataWindow();
  if (file.header().dataWindow() != window) fail(path, "corrupt EXR: header changed on re-read");
  const auto width = static_cast<std::uint32_t>(std::int64_t{window.max.x} - window.min.x + 1);
  const auto height = static_cast<std::uint32_t>(std::int64_t{window.max.y} - window.min.y + 1);
  Framebuffer image(width, height);

  // FLOAT slices straight into the framebuffer: the library converts HALF and UINT samples.
  // Slice::Make offsets the base by the window origin, so pixel (xMin, yMin) lands at (0, 0).
  const std::size_t x_stride = sizeof(vec3);
  const std::size_t y_stride = sizeof(vec3) * width;
  Imf::FrameBuffer slices;
  for (int c = 0; c < (colour.gray ? 1 : 3); ++c) {
    slices.insert(colour.names[static_cast<std::size_t>(c)],
                  Imf::Slice::Make(Imf::FLOAT, &image.pixels()[0][c], window, x_stride, y_stride));
  }
  file.setFrameBuffer(slices);
  file.readPixels(window.min.y, window.max.y);

  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      vec3& p = image.at(x, y);
      if (colour.gray) p = vec3(p.r);
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(p[c])) {
          fail(path, "EXR pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") channel " +
                         colour.names[static_cast<std::size_t>(c)] + " is NaN or infinite");
        }
      }
    }
  }
  return image;
}

} // namespace

// --- Writing files -----------------------------------------------------------------------------

namespace {

/// An image file being written. Bytes go to a temporary file beside the target, renamed over it
/// by commit() once every write, and the close, succeeded: a failed write (a full disk, a file
/// size limit) never leaves a truncated image under the requested name, and an existing image
/// stays as it was. A target that exists and is not a regular file (a device such as /dev/full, a
/// FIFO) cannot be replaced and is written directly, and so is an existing file in a folder where
/// no new file may be created. Every failure throws specula::Error naming
/// the target; the temporary file is removed unless committed.
class ImageFileWriter {
public:
  ImageFileWriter(const std::filesystem::path& path, const char* format)
      : path_(path), format_(format) {
    std::error_code ec;
    std::filesystem::path target = path;
    // A link is followed, so the image replaces the file it points to, not the link.
    if (std::filesystem::is_symlink(std::filesystem::symlink_status(path, ec))) {
      const std::filesystem::path resolved = std::filesystem::weakly_canonical(path, ec);
      if (!ec) target = resolved;
    }
    const auto status = std::filesystem::status(target, ec);
    if (std::filesystem::is_directory(status)) fail_write("is a directory");
    if (std::filesystem::exists(status) && !std::filesystem::is_regular_file(status)) {
      fd_ = ::open(target.c_str(), O_WRONLY | O_CLOEXEC);
      if (fd_ < 0) fail_write(errno_message());
      return;
    }
    static std::atomic<unsigned> counter{0};
    for (int attempt = 0; fd_ < 0; ++attempt) {
      temp_ = target;
      temp_.replace_filename("." + target.filename().string() + ".tmp-" +
                             std::to_string(::getpid()) + "-" + std::to_string(counter++));
      // 0666 before the umask, as for any new file; the rename keeps it.
      fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
      if (fd_ < 0 && (errno != EEXIST || attempt == 16)) {
        const int error = errno;
        temp_.clear();
        // A folder that takes no new file, holding a file the user may write: replaced in place,
        // as the user asked, without the guarantee.
        if ((error == EACCES || error == EPERM) && std::filesystem::is_regular_file(status)) {
          fd_ = ::open(target.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
          if (fd_ >= 0) return;
        }
        fail_write(std::error_code(error, std::generic_category()).message());
      }
    }
    final_ = target;
  }
  ImageFileWriter(const ImageFileWriter&) = delete;
  ImageFileWriter& operator=(const ImageFileWriter&) = delete;

  ~ImageFileWriter() {
    if (fd_ >= 0) ::close(fd_);
    if (!temp_.empty()) ::unlink(temp_.c_str());
  }

  /// Writes all of `bytes` at `offset` (the EXR writer seeks back to fill its offset table).
  void write_at(std::uint64_t offset, std::span<const std::uint8_t> bytes) {
    while (!bytes.empty()) {
      const ssize_t n = ::pwrite(fd_, bytes.data(), bytes.size(), static_cast<off_t>(offset));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 && errno == ESPIPE && offset == written_) { // a FIFO: only sequential writes
        write_sequential(bytes);
        return;
      }
      if (n <= 0) fail_write(n < 0 ? errno_message() : "nothing written");
      bytes = bytes.subspan(static_cast<std::size_t>(n));
      offset += static_cast<std::uint64_t>(n);
      written_ = std::max(written_, offset);
    }
  }
  void write(std::span<const std::uint8_t> bytes) { write_at(written_, bytes); }

  /// Closes the file (a close can report a delayed write error) and moves it into place.
  void commit() {
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) fail_write(errno_message());
    if (temp_.empty()) return;
    if (std::rename(temp_.c_str(), final_.c_str()) != 0) fail_write(errno_message());
    temp_.clear();
  }

  [[noreturn]] void fail_write(const std::string& reason) const {
    fail(path_, std::string("cannot write ") + format_ + ": " + reason);
  }

private:
  void write_sequential(std::span<const std::uint8_t> bytes) {
    while (!bytes.empty()) {
      const ssize_t n = ::write(fd_, bytes.data(), bytes.size());
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail_write(n < 0 ? errno_message() : "nothing written");
      bytes = bytes.subspan(static_cast<std::size_t>(n));
      written_ += static_cast<std::uint64_t>(n);
    }
  }

  std::filesystem::path path_;  ///< as the caller named it, for messages
  std::filesystem::path final_; ///< where the temporary file goes (links resolved)
  std::filesystem::path temp_;  ///< empty: writing the target directly, or committed
  const char* format_;
  int fd_ = -1;
  std::uint64_t written_ = 0;
};

/// An Imf::OStream onto an ImageFileWriter. The library writes the line offset table from
/// OutputFile's destructor, where it swallows exceptions: the first error is kept here and
/// rethrown once the OutputFile is gone.
class ExrFileOutput final : public Imf::OStream {
public:
  ExrFileOutput(ImageFileWriter& file, const std::string& name)
      : Imf::OStream(name.c_str()), file_(file) {}

  void write(const char c[], int n) override {
    if (error_) throw Iex::IoExc("earlier write failed");
    try {
      file_.write_at(position_, {reinterpret_cast<const std::uint8_t*>(c),
                                 static_cast<std::size_t>(std::max(n, 0))});
    } catch (...) {
      error_ = std::current_exception();
      throw Iex::IoExc("write failed");
    }
    position_ += static_cast<std::uint64_t>(std::max(n, 0));
  }
  std::uint64_t tellp() override { return position_; }
  void seekp(std::uint64_t position) override { position_ = position; }
  /// Rethrows the first write error, if any.
  void check() const {
    if (error_) std::rethrow_exception(error_);
  }

private:
  ImageFileWriter& file_;
  std::uint64_t position_ = 0;
  std::exception_ptr error_;
};

/// stb_image_write's callback: the encoded PNG, in one piece, onto the file.
void write_png_bytes(void* context, void* data, int size) {
  auto* writer = static_cast<std::pair<ImageFileWriter*, std::exception_ptr>*>(context);
  if (writer->second) return;
  try {
    writer->first->write({static_cast<const std::uint8_t*>(data), static_cast<std::size_t>(size)});
  } catch (...) {
    writer->second = std::current_exception(); // no exception may cross stb's C frames
  }
}

std::string extension_list(std::initializer_list<ImageFormat> formats) {
  std::string text;
  std::size_t k = 0;
  for (const ImageFormat f : formats) {
    if (k > 0) text += k + 1 == formats.size() ? " or " : ", ";
    text += f == ImageFormat::Png ? ".png" : ".exr";
    ++k;
  }
  return text;
}

} // namespace

// --- PNG ---------------------------------------------------------------------------------------

void write_png_srgb8(std::span<const std::uint8_t> rgb, std::uint32_t width, std::uint32_t height,
                     const std::filesystem::path& path) {
  if (width == 0 || height == 0 || width > kMaxFramebufferSide || height > kMaxFramebufferSide ||
      rgb.size() != std::size_t{3} * width * height) {
    fail(path, "cannot write PNG: " + std::to_string(rgb.size()) + " bytes do not form a " +
                   size_text(width, height) + " RGB image");
  }
  // Encoded in memory by stb, then written here: stbi_write_png ignores fwrite's result, so a
  // full disk would give a truncated file and success.
  ImageFileWriter file(path, "PNG");
  std::pair<ImageFileWriter*, std::exception_ptr> context{&file, nullptr};
  const int stride = static_cast<int>(3 * width);
  if (stbi_write_png_to_func(&write_png_bytes, &context, static_cast<int>(width),
                             static_cast<int>(height), 3, rgb.data(), stride) == 0) {
    file.fail_write("out of memory while encoding");
  }
  if (context.second) std::rethrow_exception(context.second);
  file.commit();
}

void write_png(const Framebuffer& image, const std::filesystem::path& path) {
  std::vector<std::uint8_t> rgb(3 * image.pixel_count());
  std::size_t i = 0;
  const Srgb8Encoder& encode = Srgb8Encoder::get();
  for (const vec3& p : image.pixels()) {
    rgb[i++] = encode(p.r);
    rgb[i++] = encode(p.g);
    rgb[i++] = encode(p.b);
  }
  write_png_srgb8(rgb, image.width(), image.height(), path);
}

Framebuffer read_png(const std::filesystem::path& path) {
  const std::string file_bytes = read_file_bytes(path, "PNG image");
  const std::span<const std::uint8_t> bytes = as_bytes(file_bytes);
  if (bytes.size() < kPngSignature.size() ||
      !std::equal(kPngSignature.begin(), kPngSignature.end(), bytes.begin())) {
    fail(path, "not a PNG file (wrong signature)");
  }
  if (bytes.size() > static_cast<std::size_t>(INT_MAX)) fail(path, "PNG file larger than 2 GiB");

  // The size is read from IHDR here rather than through stb, which reports an oversized image
  // only as "unknown image type"; checked before decoding, so a forged IHDR cannot make stb
  // allocate gigabytes. IHDR must be the first chunk: length 13, type, width, height (ISO 15948).
  constexpr std::array<std::uint8_t, 8> kIhdrStart = {0, 0, 0, 13, 'I', 'H', 'D', 'R'};
  if (bytes.size() < 24 || !std::equal(kIhdrStart.begin(), kIhdrStart.end(), bytes.begin() + 8)) {
    fail(path, "corrupt or truncated PNG: no IHDR chunk after the signature");
  }
  const auto be32 = [&](std::size_t at) {
    return std::uint64_t{bytes[at]} << 24 | std::uint64_t{bytes[at + 1]} << 16 |
           std::uint64_t{bytes[at + 2]} << 8 | std::uint64_t{bytes[at + 3]};
  };
  // Every chunk's declared length must fit in the file before stb sees it: stb grows its IDAT
  // buffer to a chunk's declared length before reading the chunk, so a 93-byte file declaring a
  // 1 GiB IDAT cost 1 GiB (a fuzzer finding, tests/data/fuzz-regressions/png/). Length, type,
  // data, CRC; lengths at most 2^31 - 1 (ISO 15948 §5.3); the walk ends at IEND.
  // Empty IDAT chunks (legal) are dropped from the copy stb decodes: stb_image copies an empty
  // chunk's zero bytes into its still-null IDAT buffer, memcpy(NULL, …, 0), which is undefined
  // behaviour (a fuzzer finding under UBSan, tests/data/fuzz-regressions/png/).
  std::string without_empty_idat;
  for (std::size_t at = kPngSignature.size(); at < bytes.size();) {
    if (bytes.size() - at < 12) fail(path, "truncated PNG: a chunk is cut short");
    const std::uint64_t chunk_length = be32(at);
    const std::string type(reinterpret_cast<const char*>(bytes.data()) + at + 4, 4);
    if (chunk_length > 0x7fffffffU || chunk_length > bytes.size() - at - 12) {
      fail(path, "truncated or corrupt PNG: chunk '" + printable(type) + "' declares " +
                     std::to_string(chunk_length) + " bytes, more than the " +
                     std::to_string(bytes.size() - at - 12) + " left in the file");
    }
    if (type == "IDAT" && chunk_length == 0 && without_empty_idat.empty()) {
      without_empty_idat.assign(file_bytes, 0, at); // the first one: copy what came before it
    } else if (!without_empty_idat.empty() && !(type == "IDAT" && chunk_length == 0)) {
      without_empty_idat.append(file_bytes, at, 12 + static_cast<std::size_t>(chunk_length));
    }
    at += 12 + static_cast<std::size_t>(chunk_length);
    if (type == "IEND") break;
  }
  const std::span<const std::uint8_t> decoded_bytes =
      without_empty_idat.empty() ? bytes : as_bytes(without_empty_idat);
  const auto* data = decoded_bytes.data();
  const int length = static_cast<int>(decoded_bytes.size());
  const std::uint64_t ihdr_width = be32(16);
  const std::uint64_t ihdr_height = be32(20);
  if (ihdr_width == 0 || ihdr_height == 0 || ihdr_width > kMaxFramebufferSide ||
      ihdr_height > kMaxFramebufferSide) {
    fail(path, "PNG size " +
                   size_text(static_cast<std::int64_t>(ihdr_width),
                             static_cast<std::int64_t>(ihdr_height)) +
                   " is outside [1, " + std::to_string(kMaxFramebufferSide) + "] per side");
  }
  // What decoding will allocate, known from IHDR before anything is: the inflated scan lines
  // (a filter byte per row), stb's unfiltered copy and RGB result, and the framebuffer.
  const std::uint64_t bit_depth = bytes[24];
  const std::uint8_t colour_type = bytes[25];
  const std::uint64_t samples = colour_type == 2   ? 3
                                : colour_type == 4 ? 2
                                : colour_type == 6 ? 4
                                                   : 1;
  const std::uint64_t row_bytes = (ihdr_width * samples * bit_depth + 7) / 8;
  const std::uint64_t raw_bytes = ihdr_height * (1 + row_bytes);
  const std::uint64_t pixels_count = ihdr_width * ihdr_height;
  // Deflate expands its input at most 1032 times (zlib's technical notes): a file too small to
  // hold the image is truncated or corrupt, whatever its IHDR says, and is refused before any
  // of the memory its IHDR asks for is allocated.
  constexpr std::uint64_t kMaxDeflateRatio = 1032;
  if (raw_bytes > kMaxDeflateRatio * bytes.size()) {
    fail(path, "corrupt or truncated PNG: a " +
                   size_text(static_cast<std::int64_t>(ihdr_width),
                             static_cast<std::int64_t>(ihdr_height)) +
                   " image needs " + std::to_string(raw_bytes) +
                   " bytes of scan lines, more than the " + std::to_string(bytes.size()) +
                   "-byte file can hold compressed");
  }
  check_memory(2 * raw_bytes + pixels_count * (6 + sizeof(vec3)),
               memory_budget({}, "--memory-limit"), path.string(),
               "decoding this " +
                   size_text(static_cast<std::int64_t>(ihdr_width),
                             static_cast<std::int64_t>(ihdr_height)) +
                   " PNG");

  int width = 0;
  int height = 0;
  int channels_in_file = 0;
  if (stbi_info_from_memory(data, length, &width, &height, &channels_in_file) == 0) {
    fail(path, "corrupt PNG: " + stbi_reason());
  }
  if (static_cast<std::uint64_t>(width) != ihdr_width ||
      static_cast<std::uint64_t>(height) != ihdr_height) {
    fail(path, "corrupt PNG: inconsistent size in IHDR");
  }

  Framebuffer image(static_cast<std::uint32_t>(width), static_cast<std::uint32_t>(height));
  auto pixels = image.pixels();
  int w = 0;
  int h = 0;
  int n = 0;
  if (stbi_is_16_bit_from_memory(data, length) != 0) {
    std::unique_ptr<stbi_us, StbiFree> decoded(
        stbi_load_16_from_memory(data, length, &w, &h, &n, 3));
    if (!decoded) fail(path, "corrupt or truncated PNG: " + stbi_reason());
    for (std::size_t i = 0; i < pixels.size(); ++i) {
      for (int c = 0; c < 3; ++c) {
        pixels[i][c] = srgb_to_linear(static_cast<float>(decoded.get()[3 * i + c]) / 65535.0f);
      }
    }
  } else {
    std::unique_ptr<stbi_uc, StbiFree> decoded(stbi_load_from_memory(data, length, &w, &h, &n, 3));
    if (!decoded) fail(path, "corrupt or truncated PNG: " + stbi_reason());
    std::array<float, 256> to_linear{};
    for (int v = 0; v < 256; ++v) to_linear[v] = srgb_to_linear(static_cast<float>(v) / 255.0f);
    for (std::size_t i = 0; i < pixels.size(); ++i) {
      for (int c = 0; c < 3; ++c) pixels[i][c] = to_linear[decoded.get()[3 * i + c]];
    }
  }
  if (w != width || h != height) fail(path, "corrupt PNG: header and image data disagree on size");
  return image;
}

// --- OpenEXR -----------------------------------------------------------------------------------

void write_exr(const Framebuffer& image, const std::filesystem::path& path) {
  const std::uint32_t width = image.width();
  const std::uint32_t height = image.height();
  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      const vec3& p = image.at(x, y);
      if (!std::isfinite(p.r) || !std::isfinite(p.g) || !std::isfinite(p.b)) {
        fail(path, "cannot write EXR: pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                       ") is NaN or infinite");
      }
    }
  }

  ImageFileWriter file(path, "EXR");
  ExrFileOutput stream(file, path.string());
  try {
    Imf::Header header(static_cast<int>(width), static_cast<int>(height));
    header.compression() = Imf::ZIP_COMPRESSION; // lossless: the floats come back bit-exact
    Imf::FrameBuffer slices;
    for (int c = 0; c < 3; ++c) {
      const char* name = c == 0 ? "R" : c == 1 ? "G" : "B";
      header.channels().insert(name, Imf::Channel(Imf::FLOAT));
      slices.insert(name, Imf::Slice::Make(Imf::FLOAT, &image.pixels()[0][c], Imath::V2i(0, 0),
                                           width, height, sizeof(vec3), sizeof(vec3) * width));
    }
    Imf::OutputFile exr(stream, header);
    exr.setFrameBuffer(slices);
    exr.writePixels(static_cast<int>(height));
  } catch (const std::exception& e) {
    stream.check(); // a write error, with its own message
    file.fail_write(one_line(e.what()));
  }
  stream.check(); // what the OutputFile's destructor wrote last (the offset table)
  file.commit();
}

Framebuffer read_exr(const std::filesystem::path& path) {
  const std::string file_bytes = read_file_bytes(path, "EXR image");
  const std::span<const std::uint8_t> bytes = as_bytes(file_bytes);
  if (bytes.size() < 4 || !Imf::isImfMagic(reinterpret_cast<const char*>(bytes.data()))) {
    fail(path, "not an OpenEXR file (wrong magic number)");
  }
  // Every failure inside the library (Iex::BaseExc, std::bad_alloc, ...) becomes a
  // specula::Error naming the file.
  try {
    return decode_exr(bytes, path);
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    fail(path, "corrupt EXR: out of memory while decoding");
  } catch (const std::exception& e) {
    fail(path, "corrupt or unreadable EXR: " + one_line(e.what()));
  }
}

// --- By extension ------------------------------------------------------------------------------

Framebuffer read_image(const std::filesystem::path& path) {
  const std::string extension = lowercase_extension(path);
  if (extension == ".png") return read_png(path);
  if (extension == ".exr") return read_exr(path);
  fail(path,
       "unsupported image extension '" + path.extension().string() + "' (expected .png or .exr)");
}

std::optional<ImageFormat> image_format(const std::filesystem::path& path) {
  const std::string extension = lowercase_extension(path);
  if (extension == ".png") return ImageFormat::Png;
  if (extension == ".exr") return ImageFormat::Exr;
  return std::nullopt;
}

ImageFormat check_image_output_path(const std::filesystem::path& path,
                                    std::initializer_list<ImageFormat> accepted) {
  if (path.empty()) throw Error("output image: the path is empty");
  const std::optional<ImageFormat> format = image_format(path);
  if (!format || std::find(accepted.begin(), accepted.end(), *format) == accepted.end()) {
    fail(path, "unsupported image extension '" + printable(path.extension().string(), 32) +
                   "' (expected " + extension_list(accepted) + ")");
  }
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(path, "is a directory, not an image file");
  const std::filesystem::path folder =
      path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(folder, ec)) {
    fail(path,
         "cannot write there: folder '" + printable(folder.string(), 200) + "' does not exist");
  }
  return *format;
}

void write_image(const Framebuffer& image, const std::filesystem::path& path) {
  if (check_image_output_path(path, {ImageFormat::Png, ImageFormat::Exr}) == ImageFormat::Png)
    return write_png(image, path);
  write_exr(image, path);
}

} // namespace specula
