#pragma once
/// \file
/// Image files: 8-bit sRGB PNG (through stb_image / stb_image_write) and a minimal OpenEXR
/// (uncompressed scan lines, written from the OpenEXR file layout document, no library).
/// Framebuffers are linear RGB; PNG stores display-encoded sRGB, EXR stores linear floats.
/// Every reader validates its input and throws specula::Error whose what() names the file and
/// the problem (missing, empty, truncated, wrong signature, absurd size, unsupported variant,
/// non-finite values); no reader trusts a size field before checking it.

#include "specula/image/framebuffer.h"

#include <cstdint>
#include <filesystem>
#include <span>

namespace specula {

/// Writes an 8-bit RGB PNG: each linear channel is clamped to [0, 1] (NaN → 0, since PNG is a
/// display format that cannot hold it), encoded with the exact piecewise sRGB OETF and rounded to
/// the nearest of 256 levels. Throws specula::Error naming the path when the file cannot be
/// written.
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

/// Writes a single-part scan-line OpenEXR 2.0 file (OpenEXR File Layout, "Scan Line Blocks"):
/// channels B, G, R as FLOAT, NO_COMPRESSION, one scan line per block, INCREASING_Y, data and
/// display window (0, 0)–(width−1, height−1). Floats are stored bit-exactly, so read_exr returns
/// an identical framebuffer. Throws specula::Error naming the path when a pixel is NaN or ±Inf
/// (Specula never writes non-finite values, and read_exr rejects them) or the file cannot be
/// written.
void write_exr(const Framebuffer& image, const std::filesystem::path& path);

/// Reads a single-part scan-line OpenEXR file without compression whose R, G and B channels are
/// FLOAT or HALF with sampling 1×1 (other channels, such as A, are skipped), in any line order.
/// The data window's origin is dropped: pixel (xMin, yMin) becomes (0, 0). Throws specula::Error
/// naming the file: missing, empty, wrong magic number, truncated header, offset table or scan
/// line, inconsistent sizes, a data window side larger than kMaxFramebufferSide, a NaN or ±Inf
/// value, or "unsupported EXR: ..." for tiled, deep, multi-part, compressed, subsampled or UINT
/// colour data.
[[nodiscard]] Framebuffer read_exr(const std::filesystem::path& path);

/// read_png or read_exr by extension (.png, .exr, case-insensitive); any other extension is an
/// error naming the file.
[[nodiscard]] Framebuffer read_image(const std::filesystem::path& path);

/// write_png or write_exr by extension (.png, .exr, case-insensitive); any other extension is an
/// error naming the file.
void write_image(const Framebuffer& image, const std::filesystem::path& path);

} // namespace specula
