#pragma once
/// \file
/// Image files: 8-bit sRGB PNG (through stb_image / stb_image_write) and OpenEXR (through the
/// OpenEXR library, every compression it implements).
/// Framebuffers are linear RGB; PNG stores display-encoded sRGB, EXR stores linear floats.
/// Every reader validates its input and throws specula::Error whose what() names the file and
/// the problem (missing, empty, truncated, wrong signature, absurd size, unsupported variant,
/// non-finite values); no reader trusts a size field before checking it.
/// Every writer encodes in memory and writes the file itself, checking each write and the close,
/// into a temporary file beside the target that is renamed over it when complete: a failed write
/// (a full disk, a missing folder, a file size limit) throws specula::Error naming the file and
/// leaves no truncated image under its name. A target that exists and is not a regular file (a
/// device such as /dev/full, a FIFO) is written directly.

#include "specula/image/framebuffer.h"

#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <span>

namespace specula {

/// Writes an 8-bit RGB PNG: each linear channel is clamped to [0, 1] (NaN → 0, since PNG is a
/// display format that cannot hold it), encoded with the exact piecewise sRGB OETF and rounded to
/// the nearest of 256 levels, whatever the path's extension. Throws specula::Error naming the path
/// when the file cannot be written.
void write_png(const Framebuffer& image, const std::filesystem::path& path);

/// Writes already display-encoded 8-bit RGB (row-major, 3 bytes per pixel, row 0 at the top), for
/// images that are not radiance, e.g. false-colour heatmaps. rgb.size() must be 3·width·height.
void write_png_srgb8(std::span<const std::uint8_t> rgb, std::uint32_t width, std::uint32_t height,
                     const std::filesystem::path& path);

/// Reads a PNG as linear RGB through the sRGB EOTF (any gAMA/iCCP chunk is ignored: PNGs are
/// taken to be sRGB). Accepts every PNG colour type (gray, gray+alpha, palette, RGB, RGBA) at 8 or
/// 16 bits per channel; gray is replicated to RGB and alpha is dropped, not composited. Throws
/// specula::Error naming the file: missing or unreadable, empty, not a PNG signature, corrupt or
/// truncated data, or a side larger than kMaxFramebufferSide.
[[nodiscard]] Framebuffer read_png(const std::filesystem::path& path);

/// Writes a single-part scan-line OpenEXR file through the OpenEXR library: channels R, G, B as
/// FLOAT, ZIP compression (lossless), INCREASING_Y, data and display window (0, 0)–(width−1,
/// height−1). Floats are stored bit-exactly, so read_exr returns an identical framebuffer.
/// Throws specula::Error naming the path when a pixel is NaN or ±Inf (Specula never writes
/// non-finite values, and read_exr rejects them; nothing is written then) or the file cannot be
/// written (missing folder, a directory, a full device).
void write_exr(const Framebuffer& image, const std::filesystem::path& path);

/// Reads a single-part OpenEXR file, scan-line or tiled (level 0 of a mip or rip map), in any
/// compression the OpenEXR library implements (NONE, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA,
/// DWAB) and any line order. Channels R, G and B of type HALF, FLOAT or UINT become floats (HALF
/// exactly, UINT above 2^24 rounded); a file with a Y channel but not all of R, G, B (and no RY,
/// BY chroma) is read as gray. Other channels, such as A, are skipped. The data window's origin is
/// dropped: pixel (xMin, yMin) becomes (0, 0). Throws specula::Error naming the file: missing,
/// empty, wrong magic number, truncated or corrupt data (the library's message, on one line), a
/// header attribute larger than the file, a missing required attribute, a data window side larger
/// than kMaxFramebufferSide (checked before any pixel memory is allocated), a NaN or ±Inf value, or
/// "unsupported EXR: ..." for multi-part, deep, luminance-chroma or subsampled colour data, or no
/// R, G, B channels.
[[nodiscard]] Framebuffer read_exr(const std::filesystem::path& path);

/// read_png or read_exr by extension (.png, .exr, case-insensitive); any other extension is an
/// error naming the file.
[[nodiscard]] Framebuffer read_image(const std::filesystem::path& path);

/// The image formats Specula writes.
enum class ImageFormat { Png, Exr };

/// The format a path's extension names (.png, .exr, case-insensitive); empty for any other.
[[nodiscard]] std::optional<ImageFormat> image_format(const std::filesystem::path& path);

/// Checks that an image of one of the `accepted` formats can be written to `path`, before the work
/// that produces it: throws specula::Error naming the path when it is empty, its extension is not
/// one of theirs (the message lists them), it names a directory, or its folder does not exist.
/// Returns the format its extension names.
ImageFormat check_image_output_path(const std::filesystem::path& path,
                                    std::initializer_list<ImageFormat> accepted);

/// write_png or write_exr by extension (.png, .exr, case-insensitive), after
/// check_image_output_path: any other extension is an error naming the file.
void write_image(const Framebuffer& image, const std::filesystem::path& path);

} // namespace specula
