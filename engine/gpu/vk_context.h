#pragma once
/// \file
/// The Vulkan side of Specula at its lowest level: one instance, one device, one compute queue
/// (which also draws where the device allows: hybrid mode's raster pass), buffers, images, compute
/// and graphics pipelines over storage buffers, and a command recorder with timestamps. Plain
/// Vulkan 1.3 C API; every failing call throws GpuError naming the call and the VkResult.
///
/// Device choice (Context::create): SPECULA_VK_DEVICE (or Options::device_name) picks the first
/// device whose name contains it (case-insensitive); otherwise a discrete GPU, then an integrated
/// one, then a virtual one, then a CPU device (lavapipe). Validation layers are enabled when asked
/// (Options::validation, on by default in Debug builds, or SPECULA_VK_VALIDATION=1) and present.

#include <vulkan/vulkan.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace specula::gpu {

/// A Vulkan call failed. device_lost() tells the one failure a caller may recover from by
/// recreating the context (or falling back to the CPU).
class GpuError : public std::runtime_error {
public:
  GpuError(const std::string& what, VkResult result);
  [[nodiscard]] VkResult result() const noexcept { return result_; }
  [[nodiscard]] bool device_lost() const noexcept { return result_ == VK_ERROR_DEVICE_LOST; }

private:
  VkResult result_;
};

/// Throws GpuError("<call>: <result name>") unless r is VK_SUCCESS.
void check(VkResult r, const char* call);
[[nodiscard]] const char* result_name(VkResult r);

/// Records a layout transition of an image's first mip level and layer (any image: Specula's own
/// and swapchain images alike), with the stages and accesses it waits for and makes wait.
void image_barrier(VkCommandBuffer cmd, VkImage image, VkImageAspectFlags aspect,
                   VkImageLayout from, VkImageLayout to, VkPipelineStageFlags src_stage,
                   VkAccessFlags src_access, VkPipelineStageFlags dst_stage,
                   VkAccessFlags dst_access);

struct DeviceInfo {
  std::string name;
  VkPhysicalDeviceType type = VK_PHYSICAL_DEVICE_TYPE_OTHER;
  std::uint32_t api_version = 0;
  std::string driver; ///< driverName (VkPhysicalDeviceVulkan12Properties)
  double timestamp_period_ns = 1.0;
  bool timestamps = false;    ///< the compute queue supports timestamp queries
  bool float64 = false;       ///< shaderFloat64 (the watertight test's double fallback)
  std::uint32_t subgroup_size = 0;
  std::uint64_t max_storage_buffer_range = 0;
  std::uint32_t max_texel_buffer_elements = 0; ///< maxTexelBufferElements (TexelBinding)
  std::uint32_t max_workgroup_count_x = 0;
  /// The queue also draws (graphics bit) and dynamic rendering is on: graphics pipelines work.
  bool graphics = false;
  /// A software rasteriser (lavapipe, SwiftShader): slower than the CPU backends, never `auto`'s.
  [[nodiscard]] bool is_cpu() const { return type == VK_PHYSICAL_DEVICE_TYPE_CPU; }
  [[nodiscard]] const char* type_name() const;
};

/// Where a buffer lives: `device` (device-local; uploads and readbacks go through a staging
/// buffer unless the memory is also host-visible, as on lavapipe and on resizable-BAR GPUs) or
/// `host` (host-visible, coherent, persistently mapped: small uniform-like data and readbacks).
enum class MemoryKind : std::uint8_t { device, host };

class Context;

/// A storage buffer with its memory. Move-only; destroyed with its context alive.
class Buffer {
public:
  Buffer() = default;
  ~Buffer();
  Buffer(Buffer&& other) noexcept;
  Buffer& operator=(Buffer&& other) noexcept;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;

  [[nodiscard]] VkBuffer handle() const { return buffer_; }
  [[nodiscard]] VkDeviceSize size() const { return size_; }
  [[nodiscard]] bool valid() const { return buffer_ != VK_NULL_HANDLE; }
  /// Mapped memory when host-visible, else nullptr.
  [[nodiscard]] void* mapped() const { return mapped_; }

  /// Copies bytes into the buffer at `offset` (a staging copy when not host-visible; waits).
  void upload(const void* data, VkDeviceSize bytes, VkDeviceSize offset = 0);
  template <class T> void upload(std::span<const T> data, VkDeviceSize offset = 0) {
    upload(data.data(), data.size_bytes(), offset);
  }
  /// Copies pieces of `data` (`bytes` long) into the buffer, each region's srcOffset into
  /// `data` and dstOffset into the buffer: one staging copy and one submit for all (waits).
  void scatter(const void* data, VkDeviceSize bytes, std::span<const VkBufferCopy> regions);
  /// Copies bytes out of the buffer (a staging copy when not host-visible; waits).
  void download(void* data, VkDeviceSize bytes, VkDeviceSize offset = 0) const;
  /// Hands `use` the buffer's bytes [offset, offset + bytes) in host memory (the mapping, or the
  /// staging copy, valid during the call): a read-back converted on the way, with no copy of
  /// its own. `use` holds the context's staging buffer: it must not upload or read back itself.
  void read(VkDeviceSize bytes, VkDeviceSize offset,
            const std::function<void(const void*)>& use) const;
  template <class T> void download(std::span<T> data, VkDeviceSize offset = 0) const {
    download(data.data(), data.size_bytes(), offset);
  }
  /// The whole buffer as texels of `format` (a TexelBinding's view), made on first use and kept
  /// with the buffer. Thread-safe.
  [[nodiscard]] VkBufferView view(VkFormat format) const;

private:
  friend class Context;
  Context* context_ = nullptr;
  VkBuffer buffer_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  VkDeviceSize size_ = 0;
  void* mapped_ = nullptr;
  mutable std::vector<std::pair<VkFormat, VkBufferView>> views_;
  void release() noexcept;
};

/// A binding of set 0 that the kernel reads as a uniform texel buffer of `format` (texelFetch
/// on a [u]samplerBuffer) instead of a storage buffer; the buffer bound there is viewed as such
/// (Buffer::view). On llvmpipe a texel fetch gathers a whole texel per lane without branching,
/// where a storage-buffer load tests and loads every lane and component on its own.
struct TexelBinding {
  std::uint32_t binding = 0;
  VkFormat format = VK_FORMAT_R32G32B32A32_UINT;
};

/// A compute pipeline whose set 0 binds `storage_buffers` buffers at bindings
/// 0..storage_buffers-1 (storage buffers, or the texel buffers `texel_buffers` names), with
/// `push_constant_bytes` of push constants and the given specialization constants
/// (constant_id i = values[i]).
struct PipelineDesc {
  std::span<const std::uint32_t> spirv;
  std::uint32_t storage_buffers = 0;
  std::uint32_t push_constant_bytes = 0;
  std::vector<std::uint32_t> specialization; ///< constant_id i → value (as 32-bit words)
  const char* debug_name = "compute";
  std::vector<TexelBinding> texel_buffers = {};
};

class Pipeline {
public:
  Pipeline() = default;
  ~Pipeline();
  Pipeline(Pipeline&& other) noexcept;
  Pipeline& operator=(Pipeline&& other) noexcept;
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  [[nodiscard]] bool valid() const { return pipeline_ != VK_NULL_HANDLE; }
  [[nodiscard]] std::uint32_t storage_buffers() const { return bindings_; }
  [[nodiscard]] std::uint32_t push_constant_bytes() const { return push_bytes_; }
  /// Set 0's layout, for a descriptor set allocated by whoever records the pipeline into a
  /// command buffer of its own (record_dispatch).
  [[nodiscard]] VkDescriptorSetLayout set_layout() const { return set_layout_; }

private:
  friend class Context;
  friend class Commands;
  friend void record_dispatch(VkCommandBuffer, VkDescriptorSet, const Pipeline&,
                              std::span<const Buffer* const>, const void*, std::uint32_t,
                              std::uint32_t, std::uint32_t);
  Context* context_ = nullptr;
  VkShaderModule module_ = VK_NULL_HANDLE;
  VkDescriptorSetLayout set_layout_ = VK_NULL_HANDLE;
  VkPipelineLayout layout_ = VK_NULL_HANDLE;
  VkPipeline pipeline_ = VK_NULL_HANDLE;
  std::uint32_t bindings_ = 0;
  std::vector<VkFormat> formats_; ///< per binding: VK_FORMAT_UNDEFINED for a storage buffer
  std::uint32_t push_bytes_ = 0;
  VkPipelineBindPoint bind_point_ = VK_PIPELINE_BIND_POINT_COMPUTE;
  VkShaderStageFlags stages_ = VK_SHADER_STAGE_COMPUTE_BIT;
  VkShaderModule fragment_ = VK_NULL_HANDLE;
  void release() noexcept;
};

/// A graphics pipeline for dynamic rendering (no render pass objects) into one colour attachment
/// of `colour_format` and a depth attachment of `depth_format`: triangle lists without vertex
/// inputs (the vertex shader pulls its vertices from storage buffers by gl_VertexIndex), no
/// culling, depth test `depth_compare` with writes, viewport and scissor set per draw. Set 0
/// binds `storage_buffers` storage buffers as PipelineDesc does, visible to both stages; push
/// constants go to the vertex stage.
struct GraphicsPipelineDesc {
  std::span<const std::uint32_t> vertex_spirv;
  std::span<const std::uint32_t> fragment_spirv;
  std::uint32_t storage_buffers = 0;
  std::uint32_t push_constant_bytes = 0;
  VkFormat colour_format = VK_FORMAT_R32G32_UINT;
  VkFormat depth_format = VK_FORMAT_D32_SFLOAT;
  VkCompareOp depth_compare = VK_COMPARE_OP_GREATER;
  const char* debug_name = "graphics";
};

/// A 2D device-local image with its memory and a view (one mip level, one layer). Move-only;
/// destroyed with its context alive.
class Image {
public:
  Image() = default;
  ~Image();
  Image(Image&& other) noexcept;
  Image& operator=(Image&& other) noexcept;
  Image(const Image&) = delete;
  Image& operator=(const Image&) = delete;

  [[nodiscard]] bool valid() const { return image_ != VK_NULL_HANDLE; }
  [[nodiscard]] VkImage handle() const { return image_; }
  [[nodiscard]] VkImageView view() const { return view_; }
  [[nodiscard]] VkFormat format() const { return format_; }
  [[nodiscard]] std::uint32_t width() const { return width_; }
  [[nodiscard]] std::uint32_t height() const { return height_; }
  [[nodiscard]] bool is_depth() const;

private:
  friend class Context;
  Context* context_ = nullptr;
  VkImage image_ = VK_NULL_HANDLE;
  VkDeviceMemory memory_ = VK_NULL_HANDLE;
  VkImageView view_ = VK_NULL_HANDLE;
  VkFormat format_ = VK_FORMAT_UNDEFINED;
  std::uint32_t width_ = 0, height_ = 0;
  void release() noexcept;
};

/// Records a dispatch of a compute `pipeline` into `cmd`, a command buffer recorded and submitted
/// elsewhere (a window's frame): `set` (allocated by the caller for pipeline.set_layout()) is
/// written with `buffers` first, so no pending submission may be using it.
void record_dispatch(VkCommandBuffer cmd, VkDescriptorSet set, const Pipeline& pipeline,
                     std::span<const Buffer* const> buffers, const void* push_constants,
                     std::uint32_t groups_x, std::uint32_t groups_y = 1,
                     std::uint32_t groups_z = 1);

/// One non-indexed draw of a graphics pipeline: vertices [0, vertex_count) of instance
/// `instance` (gl_InstanceIndex).
struct Draw {
  std::uint32_t vertex_count = 0;
  std::uint32_t instance = 0;
};

/// vkCmdUpdateBuffer's limit on one write (Commands::update).
inline constexpr VkDeviceSize kMaxCommandUpdateBytes = 65536;

/// One command buffer recorded and submitted at once: dispatches with their buffers bound,
/// barriers between them, timestamps around them. submit() waits for completion and throws
/// GpuError (device_lost() for a lost device). Every recording starts with a barrier on all
/// earlier submissions to the queue: a window's frame still reading a buffer (a device frame
/// presented in place) finishes before these commands write it. Descriptor sets are allocated per
/// dispatch from a pool the recorder owns, freed when it is destroyed.
class Commands {
public:
  explicit Commands(Context& context, std::uint32_t max_timestamps = 64);
  ~Commands();
  Commands(const Commands&) = delete;
  Commands& operator=(const Commands&) = delete;

  /// Binds `pipeline`, its buffers (one per binding, in order) and push constants, and
  /// dispatches groups_x × groups_y × groups_z workgroups.
  void dispatch(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                const void* push_constants, std::uint32_t groups_x, std::uint32_t groups_y = 1,
                std::uint32_t groups_z = 1);
  void dispatch(const Pipeline& pipeline, std::initializer_list<const Buffer*> buffers,
                const void* push_constants, std::uint32_t groups_x, std::uint32_t groups_y = 1,
                std::uint32_t groups_z = 1) {
    dispatch(pipeline, std::span<const Buffer* const>(buffers.begin(), buffers.size()),
             push_constants, groups_x, groups_y, groups_z);
  }
  /// As dispatch, with the workgroup count read from `args` at `offset` (3 uints).
  void dispatch_indirect(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                         const void* push_constants, const Buffer& args, VkDeviceSize offset = 0);
  /// Starts rendering into `colour` and `depth` (their previous contents discarded), cleared to
  /// `clear_colour` and `clear_depth`, over their whole extent.
  void begin_rendering(const Image& colour, const Image& depth,
                       const VkClearColorValue& clear_colour, float clear_depth);
  /// Binds a graphics pipeline, its buffers and push constants once, then issues `draws`
  /// (between begin_rendering and end_rendering).
  void draw(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
            const void* push_constants, std::span<const Draw> draws);
  void end_rendering();
  /// Copies a colour image just rendered (after end_rendering) into `to`, rows tightly packed;
  /// a barrier() makes the copy visible to shaders.
  void copy(const Image& from, const Buffer& to);
  /// Every shader write before is visible to every shader read/write and indirect read after.
  void barrier();
  void fill(const Buffer& buffer, std::uint32_t value, VkDeviceSize offset = 0,
            VkDeviceSize bytes = VK_WHOLE_SIZE);
  /// Writes `bytes` (a multiple of 4, at most kMaxCommandUpdateBytes) of `data` into the buffer
  /// in the command stream (vkCmdUpdateBuffer): small per-frame values into device-local memory
  /// without a staging copy or a submit of their own. A barrier() makes them visible to shaders.
  void update(const Buffer& buffer, const void* data, VkDeviceSize bytes, VkDeviceSize offset = 0);
  /// Transfer and shader writes before are visible to the host once the submit has finished
  /// (after copying device-local counters into a host-visible buffer).
  void host_barrier();
  void copy(const Buffer& from, const Buffer& to, VkDeviceSize bytes, VkDeviceSize from_offset = 0,
            VkDeviceSize to_offset = 0);
  /// Writes a timestamp after all previous commands; returns its index (0, 1, ...). Without
  /// timestamp support a no-op returning the index anyway (elapsed_ms then gives 0).
  std::uint32_t timestamp();
  /// Submits, waits, and resets for recording again (timestamps are kept until the next submit).
  void submit();
  /// Milliseconds between two timestamps of the last submit.
  [[nodiscard]] double elapsed_ms(std::uint32_t from, std::uint32_t to) const;

private:
  void begin_if_needed();
  Context& context_;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  VkDescriptorPool pool_ = VK_NULL_HANDLE;
  VkQueryPool queries_ = VK_NULL_HANDLE;
  std::uint32_t max_timestamps_ = 0;
  std::uint32_t timestamps_ = 0;
  std::vector<std::uint64_t> results_;
  bool recording_ = false;
  std::vector<VkDescriptorPool> full_pools_;
  VkDescriptorSet allocate_set(const Pipeline& pipeline);
};

class Context {
public:
  struct Options {
    /// Substring of the device name to pick (case-insensitive); empty: SPECULA_VK_DEVICE, then the
    /// preference order.
    std::string device_name;
    /// Enable VK_LAYER_KHRONOS_validation when present (also SPECULA_VK_VALIDATION=1).
#ifdef NDEBUG
    bool validation = false;
#else
    bool validation = true;
#endif
    /// Accept a CPU device (lavapipe). False: only a real GPU will do.
    bool allow_cpu = true;
    /// Map device buffers where their memory is host-visible (lavapipe, unified memory): uploads
    /// and read-backs are then plain copies. False (also SPECULA_VK_UNMAPPED=1): never, so they
    /// take the staging copies and submits of a discrete GPU's device-local memory — for tests
    /// of those paths on a device that does not need them.
    bool map_device_memory = true;
    /// Extra instance / device extensions (a window's surface and swapchain); a device without
    /// every device extension is passed over.
    std::vector<std::string> instance_extensions;
    std::vector<std::string> device_extensions;
    /// When set, only devices whose compute queue family it accepts are chosen (a window checks
    /// that the family can present to its surface); called with the new instance.
    std::function<bool(VkInstance, VkPhysicalDevice, std::uint32_t family)> accept;
  };

  /// Creates the instance and device. Throws specula::UnavailableError with a one-line reason
  /// when there is no loader, no device, or no device that fits.
  static std::unique_ptr<Context> create(const Options& options);
  static std::unique_ptr<Context> create() { return create(Options{}); }
  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  [[nodiscard]] const DeviceInfo& info() const { return info_; }
  [[nodiscard]] VkInstance instance() const { return instance_; }
  [[nodiscard]] VkDevice device() const { return device_; }
  [[nodiscard]] VkPhysicalDevice physical_device() const { return physical_; }
  [[nodiscard]] VkQueue queue() const { return queue_; }
  [[nodiscard]] std::uint32_t queue_family() const { return family_; }
  [[nodiscard]] VkCommandPool command_pool() const { return command_pool_; }
  [[nodiscard]] bool validation_enabled() const { return validation_; }
  /// Whether device buffers are mapped where they can be (Options::map_device_memory).
  [[nodiscard]] bool maps_device_memory() const { return map_device_memory_; }

  /// A storage buffer of `bytes` (at least 4) with transfer src/dst usage (and indirect).
  [[nodiscard]] Buffer make_buffer(VkDeviceSize bytes, MemoryKind kind = MemoryKind::device);
  [[nodiscard]] Pipeline make_pipeline(const PipelineDesc& desc);
  /// Throws GpuError when the device cannot draw (DeviceInfo::graphics false).
  [[nodiscard]] Pipeline make_graphics_pipeline(const GraphicsPipelineDesc& desc);
  /// A `width` × `height` image of `format`, device-local, for `usage`.
  [[nodiscard]] Image make_image(std::uint32_t width, std::uint32_t height, VkFormat format,
                                 VkImageUsageFlags usage);

  /// For tests of the recovery paths: the next submit reports VK_ERROR_DEVICE_LOST (and every
  /// later one, as a real lost device would) without touching the device.
  void simulate_device_loss() { lost_ = true; }
  [[nodiscard]] bool lost() const { return lost_; }

  /// One-shot commands on the queue, waited for (uploads, readbacks).
  void run_now(const std::function<void(VkCommandBuffer)>& record);
  /// Submits waited for so far (run_now and Commands::submit): each is a round trip between
  /// host and device, which on a discrete GPU costs tens of microseconds of a frame.
  [[nodiscard]] std::uint64_t submits() const { return submits_.load(std::memory_order_relaxed); }

  /// A host-visible buffer of at least `bytes` for one upload or read-back, held (locked) while
  /// the lease lives: the context's own, kept between calls (no allocation per frame), up to
  /// kKeptStagingBytes; a larger one is made for the lease.
  class StagingLease {
  public:
    [[nodiscard]] Buffer& buffer() { return own_.valid() ? own_ : *kept_; }

  private:
    friend class Context;
    std::unique_lock<std::mutex> lock_;
    Buffer* kept_ = nullptr;
    Buffer own_;
  };
  [[nodiscard]] StagingLease lease_staging(VkDeviceSize bytes);
  static constexpr VkDeviceSize kKeptStagingBytes = VkDeviceSize(64) << 20;

  /// The queue is shared by whoever holds the context (a window presenting from a thread of its
  /// own, a tracer rendering on the window's device): every vkQueueSubmit, vkQueuePresentKHR,
  /// vkQueueWaitIdle and vkDeviceWaitIdle holds this lock, as Vulkan asks of a queue used from
  /// several threads.
  [[nodiscard]] std::unique_lock<std::mutex> lock_queue() {
    return std::unique_lock<std::mutex>(queue_mutex_);
  }
  /// Waits until the queue has run everything submitted (vkQueueWaitIdle, locked): before
  /// replacing a buffer that another user's pending commands may still read.
  void wait_idle();

private:
  friend class Commands;
  Context() = default;
  VkInstance instance_ = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger_ = VK_NULL_HANDLE;
  VkPhysicalDevice physical_ = VK_NULL_HANDLE;
  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  std::uint32_t family_ = 0;
  VkCommandPool command_pool_ = VK_NULL_HANDLE;
  VkPhysicalDeviceMemoryProperties memory_{};
  DeviceInfo info_;
  bool validation_ = false;
  bool map_device_memory_ = true;
  bool lost_ = false;
  std::mutex queue_mutex_;
  std::atomic<std::uint64_t> submits_{0};
  /// Guards every Buffer's cache of views (Buffer::view runs wherever a dispatch is recorded).
  std::mutex views_mutex_;
  std::mutex staging_mutex_;
  std::unique_ptr<Buffer> staging_; ///< lease_staging's kept buffer
  friend class Buffer;
  /// Set 0 of p's storage buffers visible to `stages`; push constants to `push_stages`.
  static void make_layouts(VkDevice device, Pipeline& p, VkShaderStageFlags stages,
                           VkShaderStageFlags push_stages);
  [[nodiscard]] std::uint32_t memory_type(std::uint32_t bits, VkMemoryPropertyFlags want,
                                          VkMemoryPropertyFlags avoid = 0) const;
};

/// Makes `buffer` hold at least `bytes` (16 at least) of `kind`: a new buffer, the old contents
/// dropped, when it is smaller or not made yet; kept as it is otherwise. Returns whether it made
/// a new one.
bool ensure_size(Context& context, Buffer& buffer, VkDeviceSize bytes,
                 MemoryKind kind = MemoryKind::device);

/// Every Vulkan device the loader reports (empty when there is no loader or no device), for
/// `specula info` and the backend factory's availability probe. Never throws.
struct DeviceSummary {
  std::string name;
  VkPhysicalDeviceType type;
  bool compute = false;
};
[[nodiscard]] std::vector<DeviceSummary> list_devices(std::string* why_none = nullptr);

} // namespace specula::gpu
