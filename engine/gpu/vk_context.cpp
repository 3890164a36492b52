#include "specula/gpu/vk_context.h"

#include "specula/core/error.h"
#include "specula/core/log.h"

#include <dlfcn.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <utility>

#if defined(__SANITIZE_ADDRESS__)
#define SPECULA_ADDRESS_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SPECULA_ADDRESS_SANITIZER 1
#endif
#endif

namespace specula::gpu {

const char* result_name(VkResult r) {
  switch (r) {
#define SPECULA_VK_RESULT(x)                                                                       \
  case x:                                                                                          \
    return #x;
    SPECULA_VK_RESULT(VK_SUCCESS)
    SPECULA_VK_RESULT(VK_NOT_READY)
    SPECULA_VK_RESULT(VK_TIMEOUT)
    SPECULA_VK_RESULT(VK_INCOMPLETE)
    SPECULA_VK_RESULT(VK_ERROR_OUT_OF_HOST_MEMORY)
    SPECULA_VK_RESULT(VK_ERROR_OUT_OF_DEVICE_MEMORY)
    SPECULA_VK_RESULT(VK_ERROR_INITIALIZATION_FAILED)
    SPECULA_VK_RESULT(VK_ERROR_DEVICE_LOST)
    SPECULA_VK_RESULT(VK_ERROR_MEMORY_MAP_FAILED)
    SPECULA_VK_RESULT(VK_ERROR_LAYER_NOT_PRESENT)
    SPECULA_VK_RESULT(VK_ERROR_EXTENSION_NOT_PRESENT)
    SPECULA_VK_RESULT(VK_ERROR_FEATURE_NOT_PRESENT)
    SPECULA_VK_RESULT(VK_ERROR_INCOMPATIBLE_DRIVER)
    SPECULA_VK_RESULT(VK_ERROR_TOO_MANY_OBJECTS)
    SPECULA_VK_RESULT(VK_ERROR_FORMAT_NOT_SUPPORTED)
    SPECULA_VK_RESULT(VK_ERROR_FRAGMENTED_POOL)
    SPECULA_VK_RESULT(VK_ERROR_OUT_OF_POOL_MEMORY)
    SPECULA_VK_RESULT(VK_ERROR_UNKNOWN)
#undef SPECULA_VK_RESULT
  default:
    return "VkResult (other)";
  }
}

GpuError::GpuError(const std::string& what, VkResult result)
    : std::runtime_error(what + ": " + result_name(result)), result_(result) {}

void check(VkResult r, const char* call) {
  if (r != VK_SUCCESS) throw GpuError(call, r);
}

const char* DeviceInfo::type_name() const {
  switch (type) {
  case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU:
    return "discrete GPU";
  case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU:
    return "integrated GPU";
  case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU:
    return "virtual GPU";
  case VK_PHYSICAL_DEVICE_TYPE_CPU:
    return "CPU (software)";
  default:
    return "other";
  }
}

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

int type_rank(VkPhysicalDeviceType t) {
  switch (t) {
  case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU:
    return 0;
  case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU:
    return 1;
  case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU:
    return 2;
  case VK_PHYSICAL_DEVICE_TYPE_CPU:
    return 3;
  default:
    return 4;
  }
}

bool has_layer(const char* name) {
  std::uint32_t count = 0;
  if (vkEnumerateInstanceLayerProperties(&count, nullptr) != VK_SUCCESS) return false;
  std::vector<VkLayerProperties> layers(count);
  if (vkEnumerateInstanceLayerProperties(&count, layers.data()) != VK_SUCCESS) return false;
  return std::any_of(layers.begin(), layers.end(),
                     [&](const VkLayerProperties& l) { return std::strcmp(l.layerName, name) == 0; });
}

bool has_instance_extension(const char* name) {
  std::uint32_t count = 0;
  if (vkEnumerateInstanceExtensionProperties(nullptr, &count, nullptr) != VK_SUCCESS) return false;
  std::vector<VkExtensionProperties> ext(count);
  if (vkEnumerateInstanceExtensionProperties(nullptr, &count, ext.data()) != VK_SUCCESS) return false;
  return std::any_of(ext.begin(), ext.end(), [&](const VkExtensionProperties& e) {
    return std::strcmp(e.extensionName, name) == 0;
  });
}

bool has_device_extensions(VkPhysicalDevice device, const std::vector<std::string>& names) {
  if (names.empty()) return true;
  std::uint32_t count = 0;
  if (vkEnumerateDeviceExtensionProperties(device, nullptr, &count, nullptr) != VK_SUCCESS) return false;
  std::vector<VkExtensionProperties> ext(count);
  if (vkEnumerateDeviceExtensionProperties(device, nullptr, &count, ext.data()) != VK_SUCCESS)
    return false;
  return std::all_of(names.begin(), names.end(), [&](const std::string& name) {
    return std::any_of(ext.begin(), ext.end(), [&](const VkExtensionProperties& e) {
      return name == e.extensionName;
    });
  });
}

VKAPI_ATTR VkBool32 VKAPI_CALL on_validation(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                             VkDebugUtilsMessageTypeFlagsEXT,
                                             const VkDebugUtilsMessengerCallbackDataEXT* data,
                                             void*) {
  const std::string text = std::string("vulkan validation: ") + (data->pMessage ? data->pMessage : "");
  if (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT)
    log(LogLevel::Error, text);
  else
    log_warning(text);
  return VK_FALSE;
}

std::int32_t compute_family(VkPhysicalDevice device) {
  std::uint32_t count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(device, &count, nullptr);
  std::vector<VkQueueFamilyProperties> families(count);
  vkGetPhysicalDeviceQueueFamilyProperties(device, &count, families.data());
  // A compute queue with timestamps that also draws (hybrid mode's raster pass), then one with
  // timestamps, then any compute queue.
  const VkQueueFlags universal = VK_QUEUE_COMPUTE_BIT | VK_QUEUE_GRAPHICS_BIT;
  for (std::uint32_t i = 0; i < count; ++i)
    if ((families[i].queueFlags & universal) == universal && families[i].timestampValidBits > 0)
      return std::int32_t(i);
  for (std::uint32_t i = 0; i < count; ++i)
    if ((families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) && families[i].timestampValidBits > 0)
      return std::int32_t(i);
  for (std::uint32_t i = 0; i < count; ++i)
    if (families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) return std::int32_t(i);
  return -1;
}

/// Under AddressSanitizer only, before an instance is created: keeps Mesa's lavapipe loaded for
/// the rest of the process. On AMD processors the driver (Mesa 22.3's CPU detection) allocates a
/// description of the caches once per process and keeps it in a static; the loader unloads the
/// driver with the last instance, so LeakSanitizer finds the block unreferenced and fails every
/// process that used Vulkan at its exit (seen on an AMD EPYC; the Intel machines before never
/// showed it). Pinned, the block stays reachable through the driver's static, and a leak of
/// Specula's own (a Vulkan object never destroyed included) is still reported.
void pin_software_driver() {
#ifdef SPECULA_ADDRESS_SANITIZER
  static const bool pinned = dlopen("libvulkan_lvp.so", RTLD_LAZY | RTLD_NODELETE) != nullptr;
  (void)pinned;
#endif
}

/// An instance for enumeration only (no layers), or VK_NULL_HANDLE with the reason.
VkInstance bare_instance(std::string& why) {
  pin_software_driver();
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "specula";
  app.apiVersion = VK_API_VERSION_1_3;
  VkInstanceCreateInfo ci{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  ci.pApplicationInfo = &app;
  VkInstance instance = VK_NULL_HANDLE;
  const VkResult r = vkCreateInstance(&ci, nullptr, &instance);
  if (r != VK_SUCCESS) {
    why = std::string("no Vulkan instance (") + result_name(r) + ")";
    return VK_NULL_HANDLE;
  }
  return instance;
}

} // namespace

std::vector<DeviceSummary> list_devices(std::string* why_none) {
  std::string why;
  std::vector<DeviceSummary> out;
  VkInstance instance = bare_instance(why);
  if (instance != VK_NULL_HANDLE) {
    std::uint32_t count = 0;
    if (vkEnumeratePhysicalDevices(instance, &count, nullptr) == VK_SUCCESS && count > 0) {
      std::vector<VkPhysicalDevice> devices(count);
      if (vkEnumeratePhysicalDevices(instance, &count, devices.data()) == VK_SUCCESS) {
        for (VkPhysicalDevice d : devices) {
          VkPhysicalDeviceProperties p;
          vkGetPhysicalDeviceProperties(d, &p);
          out.push_back({p.deviceName, p.deviceType, compute_family(d) >= 0});
        }
      }
    }
    if (out.empty()) why = "no Vulkan device";
    vkDestroyInstance(instance, nullptr);
  }
  if (why_none != nullptr) *why_none = out.empty() ? why : std::string();
  return out;
}

std::unique_ptr<Context> Context::create(const Options& options) {
  std::unique_ptr<Context> ctx(new Context());
  ctx->map_device_memory_ = options.map_device_memory;
  if (const char* v = std::getenv("SPECULA_VK_UNMAPPED"); v != nullptr && *v != '\0')
    ctx->map_device_memory_ = std::strcmp(v, "0") == 0;
  bool validation = options.validation;
  if (const char* v = std::getenv("SPECULA_VK_VALIDATION"); v != nullptr && *v != '\0')
    validation = std::strcmp(v, "0") != 0;
  const char* kValidation = "VK_LAYER_KHRONOS_validation";
  std::vector<const char*> layers, extensions;
  if (validation) {
    if (has_layer(kValidation)) {
      layers.push_back(kValidation);
      if (has_instance_extension(VK_EXT_DEBUG_UTILS_EXTENSION_NAME))
        extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
      ctx->validation_ = true;
    } else {
      log_debug("Vulkan validation layers asked for but not installed (vulkan-validationlayers)");
    }
  }
  for (const std::string& e : options.instance_extensions) {
    if (!has_instance_extension(e.c_str()))
      throw UnavailableError("the Vulkan instance lacks extension " + e);
    extensions.push_back(e.c_str());
  }
  VkApplicationInfo app{VK_STRUCTURE_TYPE_APPLICATION_INFO};
  app.pApplicationName = "specula";
  app.pEngineName = "specula";
  app.apiVersion = VK_API_VERSION_1_3;
  VkInstanceCreateInfo ici{VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO};
  ici.pApplicationInfo = &app;
  ici.enabledLayerCount = std::uint32_t(layers.size());
  ici.ppEnabledLayerNames = layers.data();
  ici.enabledExtensionCount = std::uint32_t(extensions.size());
  ici.ppEnabledExtensionNames = extensions.data();
  pin_software_driver();
  if (const VkResult r = vkCreateInstance(&ici, nullptr, &ctx->instance_); r != VK_SUCCESS)
    throw UnavailableError(std::string("no Vulkan instance (") + result_name(r) +
                           "): is a Vulkan driver installed (mesa-vulkan-drivers)?");
  if (ctx->validation_ && has_instance_extension(VK_EXT_DEBUG_UTILS_EXTENSION_NAME)) {
    auto create_messenger = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(ctx->instance_, "vkCreateDebugUtilsMessengerEXT"));
    if (create_messenger != nullptr) {
      VkDebugUtilsMessengerCreateInfoEXT mci{VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT};
      mci.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                            VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
      mci.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                        VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                        VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
      mci.pfnUserCallback = on_validation;
      (void)create_messenger(ctx->instance_, &mci, nullptr, &ctx->messenger_);
    }
  }

  std::uint32_t count = 0;
  check(vkEnumeratePhysicalDevices(ctx->instance_, &count, nullptr), "vkEnumeratePhysicalDevices");
  std::vector<VkPhysicalDevice> devices(count);
  check(vkEnumeratePhysicalDevices(ctx->instance_, &count, devices.data()),
        "vkEnumeratePhysicalDevices");
  if (devices.empty()) throw UnavailableError("no Vulkan device on this machine");

  std::string wanted = options.device_name;
  if (wanted.empty())
    if (const char* env = std::getenv("SPECULA_VK_DEVICE"); env != nullptr) wanted = env;
  wanted = lower(wanted);

  VkPhysicalDevice best = VK_NULL_HANDLE;
  int best_rank = 1 << 30;
  std::string names;
  for (VkPhysicalDevice d : devices) {
    VkPhysicalDeviceProperties p;
    vkGetPhysicalDeviceProperties(d, &p);
    names += (names.empty() ? "" : ", ") + std::string(p.deviceName);
    if (compute_family(d) < 0 || p.apiVersion < VK_API_VERSION_1_3) continue;
    if (!options.allow_cpu && p.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) continue;
    if (!wanted.empty() && lower(p.deviceName).find(wanted) == std::string::npos) continue;
    if (!has_device_extensions(d, options.device_extensions)) continue;
    if (options.accept &&
        !options.accept(ctx->instance_, d, std::uint32_t(compute_family(d))))
      continue;
    const int rank = type_rank(p.deviceType);
    if (rank < best_rank) {
      best_rank = rank;
      best = d;
    }
  }
  if (best == VK_NULL_HANDLE) {
    if (!wanted.empty())
      throw UnavailableError("no Vulkan 1.3 compute device named like '" + wanted +
                             "' (SPECULA_VK_DEVICE); devices: " + names);
    if (!options.device_extensions.empty() || options.accept)
      throw UnavailableError("no Vulkan 1.3 device that can present here; devices: " + names);
    throw UnavailableError(options.allow_cpu
                               ? "no Vulkan 1.3 device with a compute queue; devices: " + names
                               : "no Vulkan GPU (only software devices: " + names + ")");
  }
  ctx->physical_ = best;
  ctx->family_ = std::uint32_t(compute_family(best));

  VkPhysicalDeviceVulkan12Properties p12{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_PROPERTIES};
  VkPhysicalDeviceVulkan11Properties p11{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_1_PROPERTIES};
  p11.pNext = &p12;
  VkPhysicalDeviceProperties2 props{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2};
  props.pNext = &p11;
  vkGetPhysicalDeviceProperties2(best, &props);
  VkPhysicalDeviceFeatures features;
  vkGetPhysicalDeviceFeatures(best, &features);
  VkPhysicalDeviceVulkan13Features f13{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_3_FEATURES};
  VkPhysicalDeviceFeatures2 features2{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2};
  features2.pNext = &f13;
  vkGetPhysicalDeviceFeatures2(best, &features2);
  std::uint32_t fam_count = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(best, &fam_count, nullptr);
  std::vector<VkQueueFamilyProperties> families(fam_count);
  vkGetPhysicalDeviceQueueFamilyProperties(best, &fam_count, families.data());

  DeviceInfo& info = ctx->info_;
  info.name = props.properties.deviceName;
  info.type = props.properties.deviceType;
  info.api_version = props.properties.apiVersion;
  info.driver = p12.driverName;
  info.timestamp_period_ns = props.properties.limits.timestampPeriod;
  info.timestamps = families[ctx->family_].timestampValidBits > 0 &&
                    props.properties.limits.timestampPeriod > 0.0f;
  info.float64 = features.shaderFloat64 == VK_TRUE;
  info.subgroup_size = p11.subgroupSize;
  info.max_storage_buffer_range = props.properties.limits.maxStorageBufferRange;
  info.max_texel_buffer_elements = props.properties.limits.maxTexelBufferElements;
  info.max_workgroup_count_x = props.properties.limits.maxComputeWorkGroupCount[0];
  info.graphics = (families[ctx->family_].queueFlags & VK_QUEUE_GRAPHICS_BIT) != 0 &&
                  f13.dynamicRendering == VK_TRUE;

  const float priority = 1.0f;
  VkDeviceQueueCreateInfo qci{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  qci.queueFamilyIndex = ctx->family_;
  qci.queueCount = 1;
  qci.pQueuePriorities = &priority;
  VkPhysicalDeviceFeatures enable{};
  enable.shaderFloat64 = features.shaderFloat64;
  enable.shaderInt64 = features.shaderInt64;
  VkPhysicalDeviceVulkan13Features enable13{VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_3_FEATURES};
  enable13.dynamicRendering = info.graphics ? VK_TRUE : VK_FALSE;
  VkDeviceCreateInfo dci{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  dci.pNext = &enable13;
  dci.queueCreateInfoCount = 1;
  dci.pQueueCreateInfos = &qci;
  dci.pEnabledFeatures = &enable;
  std::vector<const char*> device_extensions;
  for (const std::string& e : options.device_extensions) device_extensions.push_back(e.c_str());
  dci.enabledExtensionCount = std::uint32_t(device_extensions.size());
  dci.ppEnabledExtensionNames = device_extensions.data();
  if (const VkResult r = vkCreateDevice(best, &dci, nullptr, &ctx->device_); r != VK_SUCCESS)
    throw UnavailableError("cannot open Vulkan device '" + info.name + "' (" + result_name(r) + ")");
  vkGetDeviceQueue(ctx->device_, ctx->family_, 0, &ctx->queue_);
  VkCommandPoolCreateInfo pci{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pci.queueFamilyIndex = ctx->family_;
  check(vkCreateCommandPool(ctx->device_, &pci, nullptr, &ctx->command_pool_), "vkCreateCommandPool");
  vkGetPhysicalDeviceMemoryProperties(best, &ctx->memory_);
  log_debug("Vulkan device: " + info.name + " (" + info.type_name() + ", " + info.driver + ")");
  return ctx;
}

Context::~Context() {
  staging_.reset(); // before the device
  if (device_ != VK_NULL_HANDLE) {
    if (!lost_) (void)vkDeviceWaitIdle(device_);
    if (command_pool_ != VK_NULL_HANDLE) vkDestroyCommandPool(device_, command_pool_, nullptr);
    vkDestroyDevice(device_, nullptr);
  }
  if (messenger_ != VK_NULL_HANDLE) {
    auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
        vkGetInstanceProcAddr(instance_, "vkDestroyDebugUtilsMessengerEXT"));
    if (destroy != nullptr) destroy(instance_, messenger_, nullptr);
  }
  if (instance_ != VK_NULL_HANDLE) vkDestroyInstance(instance_, nullptr);
}

std::uint32_t Context::memory_type(std::uint32_t bits, VkMemoryPropertyFlags want,
                                   VkMemoryPropertyFlags avoid) const {
  for (std::uint32_t i = 0; i < memory_.memoryTypeCount; ++i) {
    const VkMemoryPropertyFlags f = memory_.memoryTypes[i].propertyFlags;
    if ((bits & (1u << i)) && (f & want) == want && (f & avoid) == 0) return i;
  }
  return ~0u;
}

Buffer Context::make_buffer(VkDeviceSize bytes, MemoryKind kind) {
  bytes = std::max<VkDeviceSize>(bytes, 16);
  bytes = (bytes + 15) & ~VkDeviceSize(15);
  Buffer b;
  b.context_ = this;
  b.size_ = bytes;
  VkBufferCreateInfo bci{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  bci.size = bytes;
  bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_UNIFORM_TEXEL_BUFFER_BIT |
              VK_BUFFER_USAGE_TRANSFER_SRC_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT |
              VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT;
  bci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  check(vkCreateBuffer(device_, &bci, nullptr, &b.buffer_), "vkCreateBuffer");
  VkMemoryRequirements req;
  vkGetBufferMemoryRequirements(device_, b.buffer_, &req);
  std::uint32_t type = ~0u;
  const VkMemoryPropertyFlags host =
      VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
  if (kind == MemoryKind::host) {
    type = memory_type(req.memoryTypeBits, host | VK_MEMORY_PROPERTY_HOST_CACHED_BIT);
    if (type == ~0u) type = memory_type(req.memoryTypeBits, host);
  } else {
    // Device-local memory that is not host-visible first (the fast kind on a discrete GPU; small
    // BAR heaps are kept for uploads), then any device-local memory (lavapipe, unified memory).
    type = memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT,
                       VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT);
    if (type == ~0u) type = memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
    if (type == ~0u) type = memory_type(req.memoryTypeBits, 0);
  }
  if (type == ~0u) throw GpuError("no memory type for a buffer", VK_ERROR_OUT_OF_DEVICE_MEMORY);
  VkMemoryAllocateInfo mai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  mai.allocationSize = req.size;
  mai.memoryTypeIndex = type;
  check(vkAllocateMemory(device_, &mai, nullptr, &b.memory_), "vkAllocateMemory");
  check(vkBindBufferMemory(device_, b.buffer_, b.memory_, 0), "vkBindBufferMemory");
  if ((memory_.memoryTypes[type].propertyFlags & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT) &&
      (kind == MemoryKind::host || map_device_memory_)) {
    if (memory_.memoryTypes[type].propertyFlags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT)
      check(vkMapMemory(device_, b.memory_, 0, VK_WHOLE_SIZE, 0, &b.mapped_), "vkMapMemory");
  }
  return b;
}

Context::StagingLease Context::lease_staging(VkDeviceSize bytes) {
  StagingLease lease;
  lease.lock_ = std::unique_lock<std::mutex>(staging_mutex_);
  if (bytes > kKeptStagingBytes) {
    lease.own_ = make_buffer(bytes, MemoryKind::host);
    return lease;
  }
  if (!staging_ || staging_->size() < bytes) {
    staging_.reset();
    // Grown to the next power of two (1 MiB at least): a few sizes serve every frame.
    VkDeviceSize size = VkDeviceSize(1) << 20;
    while (size < bytes) size *= 2;
    staging_ = std::make_unique<Buffer>(make_buffer(size, MemoryKind::host));
  }
  lease.kept_ = staging_.get();
  return lease;
}

void Context::run_now(const std::function<void(VkCommandBuffer)>& record) {
  if (lost_) throw GpuError("vkQueueSubmit", VK_ERROR_DEVICE_LOST);
  VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  ai.commandPool = command_pool_;
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  VkCommandBuffer cmd;
  check(vkAllocateCommandBuffers(device_, &ai, &cmd), "vkAllocateCommandBuffers");
  struct Free {
    VkDevice d;
    VkCommandPool p;
    VkCommandBuffer c;
    ~Free() { vkFreeCommandBuffers(d, p, 1, &c); }
  } guard{device_, command_pool_, cmd};
  VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  check(vkBeginCommandBuffer(cmd, &bi), "vkBeginCommandBuffer");
  record(cmd);
  check(vkEndCommandBuffer(cmd), "vkEndCommandBuffer");
  VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd;
  const std::unique_lock<std::mutex> lock = lock_queue();
  submits_.fetch_add(1, std::memory_order_relaxed);
  const VkResult r = vkQueueSubmit(queue_, 1, &si, VK_NULL_HANDLE);
  if (r == VK_ERROR_DEVICE_LOST) lost_ = true;
  check(r, "vkQueueSubmit");
  const VkResult w = vkQueueWaitIdle(queue_);
  if (w == VK_ERROR_DEVICE_LOST) lost_ = true;
  check(w, "vkQueueWaitIdle");
}

bool ensure_size(Context& context, Buffer& buffer, VkDeviceSize bytes, MemoryKind kind) {
  bytes = std::max<VkDeviceSize>(16, bytes);
  if (buffer.valid() && buffer.size() >= bytes) return false;
  buffer = context.make_buffer(bytes, kind);
  return true;
}

void Context::wait_idle() {
  if (lost_) return;
  const std::unique_lock<std::mutex> lock = lock_queue();
  const VkResult r = vkQueueWaitIdle(queue_);
  if (r == VK_ERROR_DEVICE_LOST) lost_ = true;
  check(r, "vkQueueWaitIdle");
}

// ---- Buffer ---------------------------------------------------------------------------------------

Buffer::~Buffer() { release(); }
Buffer::Buffer(Buffer&& o) noexcept { *this = std::move(o); }
Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    release();
    context_ = std::exchange(o.context_, nullptr);
    buffer_ = std::exchange(o.buffer_, VK_NULL_HANDLE);
    memory_ = std::exchange(o.memory_, VK_NULL_HANDLE);
    size_ = std::exchange(o.size_, 0);
    mapped_ = std::exchange(o.mapped_, nullptr);
    views_ = std::exchange(o.views_, {});
  }
  return *this;
}
void Buffer::release() noexcept {
  if (context_ == nullptr) return;
  VkDevice d = context_->device();
  for (const auto& [format, view] : views_) vkDestroyBufferView(d, view, nullptr);
  views_.clear();
  if (buffer_ != VK_NULL_HANDLE) vkDestroyBuffer(d, buffer_, nullptr);
  if (memory_ != VK_NULL_HANDLE) vkFreeMemory(d, memory_, nullptr); // unmaps too
  buffer_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  mapped_ = nullptr;
  context_ = nullptr;
}

VkBufferView Buffer::view(VkFormat format) const {
  const std::lock_guard lock(context_->views_mutex_);
  for (const auto& [f, view] : views_)
    if (f == format) return view;
  VkBufferViewCreateInfo ci{VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO};
  ci.buffer = buffer_;
  ci.format = format;
  ci.offset = 0;
  ci.range = VK_WHOLE_SIZE;
  VkBufferView view = VK_NULL_HANDLE;
  check(vkCreateBufferView(context_->device(), &ci, nullptr, &view), "vkCreateBufferView");
  views_.emplace_back(format, view);
  return view;
}

void Buffer::upload(const void* data, VkDeviceSize bytes, VkDeviceSize offset) {
  if (bytes == 0) return;
  if (offset + bytes > size_)
    throw GpuError("Buffer::upload beyond the buffer's end", VK_ERROR_UNKNOWN);
  if (mapped_ != nullptr) {
    std::memcpy(static_cast<char*>(mapped_) + offset, data, bytes);
    return;
  }
  Context::StagingLease lease = context_->lease_staging(bytes);
  Buffer& staging = lease.buffer();
  std::memcpy(staging.mapped(), data, bytes);
  context_->run_now([&](VkCommandBuffer cmd) {
    const VkBufferCopy region{0, offset, bytes};
    vkCmdCopyBuffer(cmd, staging.handle(), buffer_, 1, &region);
  });
}

void Buffer::scatter(const void* data, VkDeviceSize bytes, std::span<const VkBufferCopy> regions) {
  if (regions.empty()) return;
  for (const VkBufferCopy& r : regions)
    if (r.srcOffset + r.size > bytes || r.dstOffset + r.size > size_)
      throw GpuError("Buffer::scatter beyond its data or the buffer's end", VK_ERROR_UNKNOWN);
  const auto* from = static_cast<const char*>(data);
  if (mapped_ != nullptr) {
    for (const VkBufferCopy& r : regions)
      std::memcpy(static_cast<char*>(mapped_) + r.dstOffset, from + r.srcOffset, r.size);
    return;
  }
  Context::StagingLease lease = context_->lease_staging(bytes);
  Buffer& staging = lease.buffer();
  std::memcpy(staging.mapped(), data, bytes);
  context_->run_now([&](VkCommandBuffer cmd) {
    vkCmdCopyBuffer(cmd, staging.handle(), buffer_, std::uint32_t(regions.size()), regions.data());
  });
}

void Buffer::read(VkDeviceSize bytes, VkDeviceSize offset,
                  const std::function<void(const void*)>& use) const {
  if (bytes == 0) return;
  if (offset + bytes > size_)
    throw GpuError("Buffer::read beyond the buffer's end", VK_ERROR_UNKNOWN);
  if (mapped_ != nullptr) {
    use(static_cast<const char*>(mapped_) + offset);
    return;
  }
  Context::StagingLease lease = context_->lease_staging(bytes);
  Buffer& staging = lease.buffer();
  context_->run_now([&](VkCommandBuffer cmd) {
    const VkBufferCopy region{offset, 0, bytes};
    vkCmdCopyBuffer(cmd, buffer_, staging.handle(), 1, &region);
  });
  use(staging.mapped());
}

void Buffer::download(void* data, VkDeviceSize bytes, VkDeviceSize offset) const {
  read(bytes, offset, [&](const void* from) { std::memcpy(data, from, bytes); });
}

// ---- Pipeline -------------------------------------------------------------------------------------

Pipeline::~Pipeline() { release(); }
Pipeline::Pipeline(Pipeline&& o) noexcept { *this = std::move(o); }
Pipeline& Pipeline::operator=(Pipeline&& o) noexcept {
  if (this != &o) {
    release();
    context_ = std::exchange(o.context_, nullptr);
    module_ = std::exchange(o.module_, VK_NULL_HANDLE);
    set_layout_ = std::exchange(o.set_layout_, VK_NULL_HANDLE);
    layout_ = std::exchange(o.layout_, VK_NULL_HANDLE);
    pipeline_ = std::exchange(o.pipeline_, VK_NULL_HANDLE);
    bindings_ = o.bindings_;
    formats_ = std::move(o.formats_);
    push_bytes_ = o.push_bytes_;
    bind_point_ = o.bind_point_;
    stages_ = o.stages_;
    fragment_ = std::exchange(o.fragment_, VK_NULL_HANDLE);
  }
  return *this;
}
void Pipeline::release() noexcept {
  if (context_ == nullptr) return;
  VkDevice d = context_->device();
  if (fragment_ != VK_NULL_HANDLE) vkDestroyShaderModule(d, fragment_, nullptr);
  fragment_ = VK_NULL_HANDLE;
  if (pipeline_ != VK_NULL_HANDLE) vkDestroyPipeline(d, pipeline_, nullptr);
  if (layout_ != VK_NULL_HANDLE) vkDestroyPipelineLayout(d, layout_, nullptr);
  if (set_layout_ != VK_NULL_HANDLE) vkDestroyDescriptorSetLayout(d, set_layout_, nullptr);
  if (module_ != VK_NULL_HANDLE) vkDestroyShaderModule(d, module_, nullptr);
  pipeline_ = VK_NULL_HANDLE;
  context_ = nullptr;
}

namespace {
VkShaderModule make_module(VkDevice device, std::span<const std::uint32_t> spirv) {
  VkShaderModuleCreateInfo smci{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  smci.codeSize = spirv.size_bytes();
  smci.pCode = spirv.data();
  VkShaderModule module = VK_NULL_HANDLE;
  check(vkCreateShaderModule(device, &smci, nullptr, &module), "vkCreateShaderModule");
  return module;
}
} // namespace

void Context::make_layouts(VkDevice device, Pipeline& p, VkShaderStageFlags stages,
                  VkShaderStageFlags push_stages) {
  std::vector<VkDescriptorSetLayoutBinding> bindings(p.bindings_);
  p.formats_.resize(p.bindings_, VK_FORMAT_UNDEFINED);
  for (std::uint32_t i = 0; i < p.bindings_; ++i)
    bindings[i] = {i,
                   p.formats_[i] == VK_FORMAT_UNDEFINED ? VK_DESCRIPTOR_TYPE_STORAGE_BUFFER
                                                        : VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER,
                   1, stages, nullptr};
  VkDescriptorSetLayoutCreateInfo dlci{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  dlci.bindingCount = p.bindings_;
  dlci.pBindings = bindings.data();
  check(vkCreateDescriptorSetLayout(device, &dlci, nullptr, &p.set_layout_),
        "vkCreateDescriptorSetLayout");
  VkPushConstantRange range{push_stages, 0, p.push_bytes_};
  VkPipelineLayoutCreateInfo plci{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  plci.setLayoutCount = 1;
  plci.pSetLayouts = &p.set_layout_;
  plci.pushConstantRangeCount = p.push_bytes_ > 0 ? 1 : 0;
  plci.pPushConstantRanges = &range;
  check(vkCreatePipelineLayout(device, &plci, nullptr, &p.layout_), "vkCreatePipelineLayout");
  p.stages_ = push_stages;
}

Pipeline Context::make_graphics_pipeline(const GraphicsPipelineDesc& desc) {
  if (!info_.graphics)
    throw GpuError(std::string(desc.debug_name) + ": the device's queue cannot draw (no graphics "
                                                  "bit or no dynamic rendering)",
                   VK_ERROR_FEATURE_NOT_PRESENT);
  Pipeline p;
  p.context_ = this;
  p.bindings_ = desc.storage_buffers;
  p.push_bytes_ = desc.push_constant_bytes;
  p.bind_point_ = VK_PIPELINE_BIND_POINT_GRAPHICS;
  p.module_ = make_module(device_, desc.vertex_spirv);
  p.fragment_ = make_module(device_, desc.fragment_spirv);
  make_layouts(device_, p, VK_SHADER_STAGE_VERTEX_BIT | VK_SHADER_STAGE_FRAGMENT_BIT,
               VK_SHADER_STAGE_VERTEX_BIT);

  VkPipelineShaderStageCreateInfo stages[2] = {
      {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO},
      {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO}};
  stages[0].stage = VK_SHADER_STAGE_VERTEX_BIT;
  stages[0].module = p.module_;
  stages[0].pName = "main";
  stages[1].stage = VK_SHADER_STAGE_FRAGMENT_BIT;
  stages[1].module = p.fragment_;
  stages[1].pName = "main";
  VkPipelineVertexInputStateCreateInfo vertex_input{
      VK_STRUCTURE_TYPE_PIPELINE_VERTEX_INPUT_STATE_CREATE_INFO};
  VkPipelineInputAssemblyStateCreateInfo assembly{
      VK_STRUCTURE_TYPE_PIPELINE_INPUT_ASSEMBLY_STATE_CREATE_INFO};
  assembly.topology = VK_PRIMITIVE_TOPOLOGY_TRIANGLE_LIST;
  VkPipelineViewportStateCreateInfo viewport{VK_STRUCTURE_TYPE_PIPELINE_VIEWPORT_STATE_CREATE_INFO};
  viewport.viewportCount = 1;
  viewport.scissorCount = 1;
  VkPipelineRasterizationStateCreateInfo raster{
      VK_STRUCTURE_TYPE_PIPELINE_RASTERIZATION_STATE_CREATE_INFO};
  raster.polygonMode = VK_POLYGON_MODE_FILL;
  raster.cullMode = VK_CULL_MODE_NONE;
  raster.frontFace = VK_FRONT_FACE_COUNTER_CLOCKWISE;
  raster.lineWidth = 1.0f;
  VkPipelineMultisampleStateCreateInfo multisample{
      VK_STRUCTURE_TYPE_PIPELINE_MULTISAMPLE_STATE_CREATE_INFO};
  multisample.rasterizationSamples = VK_SAMPLE_COUNT_1_BIT;
  VkPipelineDepthStencilStateCreateInfo depth{
      VK_STRUCTURE_TYPE_PIPELINE_DEPTH_STENCIL_STATE_CREATE_INFO};
  depth.depthTestEnable = VK_TRUE;
  depth.depthWriteEnable = VK_TRUE;
  depth.depthCompareOp = desc.depth_compare;
  VkPipelineColorBlendAttachmentState attachment{};
  attachment.colorWriteMask = VK_COLOR_COMPONENT_R_BIT | VK_COLOR_COMPONENT_G_BIT |
                              VK_COLOR_COMPONENT_B_BIT | VK_COLOR_COMPONENT_A_BIT;
  VkPipelineColorBlendStateCreateInfo blend{
      VK_STRUCTURE_TYPE_PIPELINE_COLOR_BLEND_STATE_CREATE_INFO};
  blend.attachmentCount = 1;
  blend.pAttachments = &attachment;
  const VkDynamicState dynamic_states[2] = {VK_DYNAMIC_STATE_VIEWPORT, VK_DYNAMIC_STATE_SCISSOR};
  VkPipelineDynamicStateCreateInfo dynamic{VK_STRUCTURE_TYPE_PIPELINE_DYNAMIC_STATE_CREATE_INFO};
  dynamic.dynamicStateCount = 2;
  dynamic.pDynamicStates = dynamic_states;
  VkPipelineRenderingCreateInfo rendering{VK_STRUCTURE_TYPE_PIPELINE_RENDERING_CREATE_INFO};
  rendering.colorAttachmentCount = 1;
  rendering.pColorAttachmentFormats = &desc.colour_format;
  rendering.depthAttachmentFormat = desc.depth_format;

  VkGraphicsPipelineCreateInfo gpci{VK_STRUCTURE_TYPE_GRAPHICS_PIPELINE_CREATE_INFO};
  gpci.pNext = &rendering;
  gpci.stageCount = 2;
  gpci.pStages = stages;
  gpci.pVertexInputState = &vertex_input;
  gpci.pInputAssemblyState = &assembly;
  gpci.pViewportState = &viewport;
  gpci.pRasterizationState = &raster;
  gpci.pMultisampleState = &multisample;
  gpci.pDepthStencilState = &depth;
  gpci.pColorBlendState = &blend;
  gpci.pDynamicState = &dynamic;
  gpci.layout = p.layout_;
  check(vkCreateGraphicsPipelines(device_, VK_NULL_HANDLE, 1, &gpci, nullptr, &p.pipeline_),
        desc.debug_name);
  return p;
}

// ---- Image ----------------------------------------------------------------------------------------

Image::~Image() { release(); }
Image::Image(Image&& o) noexcept { *this = std::move(o); }
Image& Image::operator=(Image&& o) noexcept {
  if (this != &o) {
    release();
    context_ = std::exchange(o.context_, nullptr);
    image_ = std::exchange(o.image_, VK_NULL_HANDLE);
    memory_ = std::exchange(o.memory_, VK_NULL_HANDLE);
    view_ = std::exchange(o.view_, VK_NULL_HANDLE);
    format_ = o.format_;
    width_ = o.width_;
    height_ = o.height_;
  }
  return *this;
}
void Image::release() noexcept {
  if (context_ == nullptr) return;
  VkDevice d = context_->device();
  if (view_ != VK_NULL_HANDLE) vkDestroyImageView(d, view_, nullptr);
  if (image_ != VK_NULL_HANDLE) vkDestroyImage(d, image_, nullptr);
  if (memory_ != VK_NULL_HANDLE) vkFreeMemory(d, memory_, nullptr);
  view_ = VK_NULL_HANDLE;
  image_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  context_ = nullptr;
}
bool Image::is_depth() const {
  return format_ == VK_FORMAT_D32_SFLOAT || format_ == VK_FORMAT_D16_UNORM ||
         format_ == VK_FORMAT_X8_D24_UNORM_PACK32;
}

Image Context::make_image(std::uint32_t width, std::uint32_t height, VkFormat format,
                          VkImageUsageFlags usage) {
  Image img;
  img.context_ = this;
  img.format_ = format;
  img.width_ = width;
  img.height_ = height;
  VkImageCreateInfo ici{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  ici.imageType = VK_IMAGE_TYPE_2D;
  ici.format = format;
  ici.extent = {width, height, 1};
  ici.mipLevels = 1;
  ici.arrayLayers = 1;
  ici.samples = VK_SAMPLE_COUNT_1_BIT;
  ici.tiling = VK_IMAGE_TILING_OPTIMAL;
  ici.usage = usage;
  ici.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ici.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  check(vkCreateImage(device_, &ici, nullptr, &img.image_), "vkCreateImage");
  VkMemoryRequirements req;
  vkGetImageMemoryRequirements(device_, img.image_, &req);
  std::uint32_t type = memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (type == ~0u) type = memory_type(req.memoryTypeBits, 0);
  if (type == ~0u) throw GpuError("no memory type for an image", VK_ERROR_OUT_OF_DEVICE_MEMORY);
  VkMemoryAllocateInfo mai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  mai.allocationSize = req.size;
  mai.memoryTypeIndex = type;
  check(vkAllocateMemory(device_, &mai, nullptr, &img.memory_), "vkAllocateMemory");
  check(vkBindImageMemory(device_, img.image_, img.memory_, 0), "vkBindImageMemory");
  VkImageViewCreateInfo vci{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  vci.image = img.image_;
  vci.viewType = VK_IMAGE_VIEW_TYPE_2D;
  vci.format = format;
  vci.subresourceRange = {
      VkImageAspectFlags(img.is_depth() ? VK_IMAGE_ASPECT_DEPTH_BIT : VK_IMAGE_ASPECT_COLOR_BIT), 0,
      1, 0, 1};
  check(vkCreateImageView(device_, &vci, nullptr, &img.view_), "vkCreateImageView");
  return img;
}

Pipeline Context::make_pipeline(const PipelineDesc& desc) {
  Pipeline p;
  p.context_ = this;
  p.bindings_ = desc.storage_buffers;
  p.formats_.assign(p.bindings_, VK_FORMAT_UNDEFINED);
  for (const TexelBinding& t : desc.texel_buffers) {
    if (t.binding >= p.bindings_)
      throw GpuError(std::string(desc.debug_name) + ": texel buffer binding " +
                         std::to_string(t.binding) + " past its " + std::to_string(p.bindings_) +
                         " bindings",
                     VK_ERROR_UNKNOWN);
    p.formats_[t.binding] = t.format;
  }
  p.push_bytes_ = desc.push_constant_bytes;
  p.module_ = make_module(device_, desc.spirv);
  make_layouts(device_, p, VK_SHADER_STAGE_COMPUTE_BIT, VK_SHADER_STAGE_COMPUTE_BIT);
  std::vector<VkSpecializationMapEntry> entries(desc.specialization.size());
  for (std::uint32_t i = 0; i < entries.size(); ++i)
    entries[i] = {i, std::uint32_t(i * sizeof(std::uint32_t)), sizeof(std::uint32_t)};
  VkSpecializationInfo spec{};
  spec.mapEntryCount = std::uint32_t(entries.size());
  spec.pMapEntries = entries.data();
  spec.dataSize = desc.specialization.size() * sizeof(std::uint32_t);
  spec.pData = desc.specialization.data();
  VkComputePipelineCreateInfo cpci{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  cpci.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
  cpci.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  cpci.stage.module = p.module_;
  cpci.stage.pName = "main";
  cpci.stage.pSpecializationInfo = entries.empty() ? nullptr : &spec;
  cpci.layout = p.layout_;
  check(vkCreateComputePipelines(device_, VK_NULL_HANDLE, 1, &cpci, nullptr, &p.pipeline_),
        desc.debug_name);
  return p;
}

// ---- Commands -------------------------------------------------------------------------------------

namespace {
VkDescriptorPool make_pool(VkDevice device) {
  const VkDescriptorPoolSize sizes[] = {{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1024},
                                        {VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER, 256}};
  VkDescriptorPoolCreateInfo ci{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  ci.maxSets = 128;
  ci.poolSizeCount = 2;
  ci.pPoolSizes = sizes;
  VkDescriptorPool pool;
  check(vkCreateDescriptorPool(device, &ci, nullptr, &pool), "vkCreateDescriptorPool");
  return pool;
}
} // namespace

Commands::Commands(Context& context, std::uint32_t max_timestamps)
    : context_(context), max_timestamps_(max_timestamps) {
  VkDevice d = context.device();
  VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  ai.commandPool = context.command_pool();
  ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  ai.commandBufferCount = 1;
  check(vkAllocateCommandBuffers(d, &ai, &cmd_), "vkAllocateCommandBuffers");
  VkFenceCreateInfo fci{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  check(vkCreateFence(d, &fci, nullptr, &fence_), "vkCreateFence");
  pool_ = make_pool(d);
  if (context.info().timestamps && max_timestamps > 0) {
    VkQueryPoolCreateInfo qci{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
    qci.queryType = VK_QUERY_TYPE_TIMESTAMP;
    qci.queryCount = max_timestamps;
    check(vkCreateQueryPool(d, &qci, nullptr, &queries_), "vkCreateQueryPool");
  }
}

Commands::~Commands() {
  VkDevice d = context_.device();
  if (recording_) (void)vkEndCommandBuffer(cmd_);
  if (queries_ != VK_NULL_HANDLE) vkDestroyQueryPool(d, queries_, nullptr);
  for (VkDescriptorPool p : full_pools_) vkDestroyDescriptorPool(d, p, nullptr);
  vkDestroyDescriptorPool(d, pool_, nullptr);
  vkDestroyFence(d, fence_, nullptr);
  vkFreeCommandBuffers(d, context_.command_pool(), 1, &cmd_);
}

void Commands::begin_if_needed() {
  if (recording_) return;
  VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  check(vkBeginCommandBuffer(cmd_, &bi), "vkBeginCommandBuffer");
  if (queries_ != VK_NULL_HANDLE) vkCmdResetQueryPool(cmd_, queries_, 0, max_timestamps_);
  // Submissions are not ordered among themselves: a window's frame submitted earlier may still
  // read a buffer these commands write (a device frame's image, presented in place).
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = VK_ACCESS_MEMORY_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_MEMORY_READ_BIT | VK_ACCESS_MEMORY_WRITE_BIT;
  vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, VK_PIPELINE_STAGE_ALL_COMMANDS_BIT,
                       0, 1, &mb, 0, nullptr, 0, nullptr);
  timestamps_ = 0;
  recording_ = true;
}

VkDescriptorSet Commands::allocate_set(const Pipeline& pipeline) {
  VkDescriptorSetAllocateInfo ai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  ai.descriptorPool = pool_;
  ai.descriptorSetCount = 1;
  ai.pSetLayouts = &pipeline.set_layout_;
  VkDescriptorSet set;
  VkResult r = vkAllocateDescriptorSets(context_.device(), &ai, &set);
  if (r == VK_ERROR_OUT_OF_POOL_MEMORY || r == VK_ERROR_FRAGMENTED_POOL) {
    full_pools_.push_back(pool_);
    pool_ = make_pool(context_.device());
    ai.descriptorPool = pool_;
    r = vkAllocateDescriptorSets(context_.device(), &ai, &set);
  }
  check(r, "vkAllocateDescriptorSets");
  return set;
}

namespace {
void bind_set(VkDevice device, VkCommandBuffer cmd, VkDescriptorSet set, VkPipeline pipeline,
              VkPipelineLayout layout, std::span<const VkFormat> formats,
              std::span<const Buffer* const> buffers, const void* push, std::uint32_t push_bytes,
              VkPipelineBindPoint bind_point = VK_PIPELINE_BIND_POINT_COMPUTE,
              VkShaderStageFlags push_stages = VK_SHADER_STAGE_COMPUTE_BIT) {
  std::vector<VkDescriptorBufferInfo> infos(buffers.size());
  std::vector<VkBufferView> views(buffers.size());
  std::vector<VkWriteDescriptorSet> writes(buffers.size());
  for (std::size_t i = 0; i < buffers.size(); ++i) {
    writes[i] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    writes[i].dstSet = set;
    writes[i].dstBinding = std::uint32_t(i);
    writes[i].descriptorCount = 1;
    if (i < formats.size() && formats[i] != VK_FORMAT_UNDEFINED) {
      views[i] = buffers[i]->view(formats[i]);
      writes[i].descriptorType = VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER;
      writes[i].pTexelBufferView = &views[i];
    } else {
      infos[i] = {buffers[i]->handle(), 0, VK_WHOLE_SIZE};
      writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
      writes[i].pBufferInfo = &infos[i];
    }
  }
  vkUpdateDescriptorSets(device, std::uint32_t(writes.size()), writes.data(), 0, nullptr);
  vkCmdBindPipeline(cmd, bind_point, pipeline);
  vkCmdBindDescriptorSets(cmd, bind_point, layout, 0, 1, &set, 0, nullptr);
  if (push_bytes > 0 && push != nullptr)
    vkCmdPushConstants(cmd, layout, push_stages, 0, push_bytes, push);
}

/// A layout transition of a whole single-level image.
void transition(VkCommandBuffer cmd, const Image& image, VkImageLayout from, VkImageLayout to,
                VkPipelineStageFlags src_stage, VkAccessFlags src_access,
                VkPipelineStageFlags dst_stage, VkAccessFlags dst_access) {
  image_barrier(cmd, image.handle(),
                image.is_depth() ? VK_IMAGE_ASPECT_DEPTH_BIT : VK_IMAGE_ASPECT_COLOR_BIT, from, to,
                src_stage, src_access, dst_stage, dst_access);
}
} // namespace

void record_dispatch(VkCommandBuffer cmd, VkDescriptorSet set, const Pipeline& pipeline,
                     std::span<const Buffer* const> buffers, const void* push_constants,
                     std::uint32_t groups_x, std::uint32_t groups_y, std::uint32_t groups_z) {
  if (buffers.size() != pipeline.bindings_)
    throw GpuError("record_dispatch: " + std::to_string(buffers.size()) + " buffers for " +
                       std::to_string(pipeline.bindings_) + " bindings",
                   VK_ERROR_UNKNOWN);
  bind_set(pipeline.context_->device(), cmd, set, pipeline.pipeline_, pipeline.layout_,
           pipeline.formats_, buffers, push_constants, pipeline.push_bytes_);
  if (groups_x > 0 && groups_y > 0 && groups_z > 0)
    vkCmdDispatch(cmd, groups_x, groups_y, groups_z);
}

void image_barrier(VkCommandBuffer cmd, VkImage image, VkImageAspectFlags aspect,
                   VkImageLayout from, VkImageLayout to, VkPipelineStageFlags src_stage,
                   VkAccessFlags src_access, VkPipelineStageFlags dst_stage,
                   VkAccessFlags dst_access) {
  VkImageMemoryBarrier b{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  b.srcAccessMask = src_access;
  b.dstAccessMask = dst_access;
  b.oldLayout = from;
  b.newLayout = to;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image;
  b.subresourceRange = {aspect, 0, 1, 0, 1};
  vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 0, nullptr, 0, nullptr, 1, &b);
}

void Commands::dispatch(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                        const void* push_constants, std::uint32_t gx, std::uint32_t gy,
                        std::uint32_t gz) {
  if (buffers.size() != pipeline.bindings_)
    throw GpuError(std::string("dispatch: wrong buffer count for ") + "a pipeline",
                   VK_ERROR_UNKNOWN);
  begin_if_needed();
  const VkDescriptorSet set = allocate_set(pipeline);
  bind_set(context_.device(), cmd_, set, pipeline.pipeline_, pipeline.layout_, pipeline.formats_,
           buffers, push_constants, pipeline.push_bytes_);
  if (gx > 0 && gy > 0 && gz > 0) vkCmdDispatch(cmd_, gx, gy, gz);
}

void Commands::dispatch_indirect(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                                 const void* push_constants, const Buffer& args,
                                 VkDeviceSize offset) {
  if (buffers.size() != pipeline.bindings_)
    throw GpuError("dispatch_indirect: wrong buffer count", VK_ERROR_UNKNOWN);
  begin_if_needed();
  const VkDescriptorSet set = allocate_set(pipeline);
  bind_set(context_.device(), cmd_, set, pipeline.pipeline_, pipeline.layout_, pipeline.formats_,
           buffers, push_constants, pipeline.push_bytes_);
  vkCmdDispatchIndirect(cmd_, args.handle(), offset);
}

void Commands::begin_rendering(const Image& colour, const Image& depth,
                               const VkClearColorValue& clear_colour, float clear_depth) {
  begin_if_needed();
  // From UNDEFINED: the previous contents are not wanted, only the end of earlier reads (a copy).
  transition(cmd_, colour, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL,
             VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT,
             VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT);
  transition(cmd_, depth, VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL,
             VK_PIPELINE_STAGE_ALL_COMMANDS_BIT, 0,
             VK_PIPELINE_STAGE_EARLY_FRAGMENT_TESTS_BIT | VK_PIPELINE_STAGE_LATE_FRAGMENT_TESTS_BIT,
             VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_READ_BIT |
                 VK_ACCESS_DEPTH_STENCIL_ATTACHMENT_WRITE_BIT);
  VkRenderingAttachmentInfo colour_info{VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO};
  colour_info.imageView = colour.view();
  colour_info.imageLayout = VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL;
  colour_info.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
  colour_info.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  colour_info.clearValue.color = clear_colour;
  VkRenderingAttachmentInfo depth_info{VK_STRUCTURE_TYPE_RENDERING_ATTACHMENT_INFO};
  depth_info.imageView = depth.view();
  depth_info.imageLayout = VK_IMAGE_LAYOUT_DEPTH_ATTACHMENT_OPTIMAL;
  depth_info.loadOp = VK_ATTACHMENT_LOAD_OP_CLEAR;
  depth_info.storeOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  depth_info.clearValue.depthStencil = {clear_depth, 0};
  VkRenderingInfo ri{VK_STRUCTURE_TYPE_RENDERING_INFO};
  ri.renderArea = {{0, 0}, {colour.width(), colour.height()}};
  ri.layerCount = 1;
  ri.colorAttachmentCount = 1;
  ri.pColorAttachments = &colour_info;
  ri.pDepthAttachment = &depth_info;
  vkCmdBeginRendering(cmd_, &ri);
  const VkViewport viewport{0.0f, 0.0f, float(colour.width()), float(colour.height()), 0.0f, 1.0f};
  const VkRect2D scissor{{0, 0}, {colour.width(), colour.height()}};
  vkCmdSetViewport(cmd_, 0, 1, &viewport);
  vkCmdSetScissor(cmd_, 0, 1, &scissor);
}

void Commands::draw(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                    const void* push_constants, std::span<const Draw> draws) {
  if (buffers.size() != pipeline.bindings_ ||
      pipeline.bind_point_ != VK_PIPELINE_BIND_POINT_GRAPHICS)
    throw GpuError("draw: not a graphics pipeline, or the wrong buffer count", VK_ERROR_UNKNOWN);
  begin_if_needed();
  const VkDescriptorSet set = allocate_set(pipeline);
  bind_set(context_.device(), cmd_, set, pipeline.pipeline_, pipeline.layout_, pipeline.formats_,
           buffers, push_constants, pipeline.push_bytes_, VK_PIPELINE_BIND_POINT_GRAPHICS,
           pipeline.stages_);
  for (const Draw& d : draws)
    if (d.vertex_count > 0) vkCmdDraw(cmd_, d.vertex_count, 1, 0, d.instance);
}

void Commands::end_rendering() {
  begin_if_needed();
  vkCmdEndRendering(cmd_);
}

void Commands::copy(const Image& from, const Buffer& to) {
  begin_if_needed();
  transition(cmd_, from, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL,
             VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT,
             VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT,
             VK_ACCESS_TRANSFER_READ_BIT);
  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {from.width(), from.height(), 1};
  vkCmdCopyImageToBuffer(cmd_, from.handle(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, to.handle(), 1,
                         &region);
}

void Commands::barrier() {
  begin_if_needed();
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT |
                     VK_ACCESS_INDIRECT_COMMAND_READ_BIT | VK_ACCESS_TRANSFER_READ_BIT |
                     VK_ACCESS_TRANSFER_WRITE_BIT;
  vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_DRAW_INDIRECT_BIT |
                           VK_PIPELINE_STAGE_TRANSFER_BIT,
                       0, 1, &mb, 0, nullptr, 0, nullptr);
}

void Commands::fill(const Buffer& buffer, std::uint32_t value, VkDeviceSize offset,
                    VkDeviceSize bytes) {
  begin_if_needed();
  vkCmdFillBuffer(cmd_, buffer.handle(), offset, bytes, value);
}

void Commands::update(const Buffer& buffer, const void* data, VkDeviceSize bytes,
                      VkDeviceSize offset) {
  if (bytes == 0) return;
  if (bytes % 4 != 0 || bytes > kMaxCommandUpdateBytes || offset + bytes > buffer.size())
    throw GpuError("Commands::update: " + std::to_string(bytes) + " bytes at " +
                       std::to_string(offset) + " (a multiple of 4, at most 65536, in the buffer)",
                   VK_ERROR_UNKNOWN);
  begin_if_needed();
  vkCmdUpdateBuffer(cmd_, buffer.handle(), offset, bytes, data);
}

void Commands::host_barrier() {
  begin_if_needed();
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  vkCmdPipelineBarrier(cmd_, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
}

void Commands::copy(const Buffer& from, const Buffer& to, VkDeviceSize bytes,
                    VkDeviceSize from_offset, VkDeviceSize to_offset) {
  begin_if_needed();
  const VkBufferCopy region{from_offset, to_offset, bytes};
  vkCmdCopyBuffer(cmd_, from.handle(), to.handle(), 1, &region);
}

std::uint32_t Commands::timestamp() {
  begin_if_needed();
  const std::uint32_t index = timestamps_++;
  if (queries_ != VK_NULL_HANDLE && index < max_timestamps_)
    vkCmdWriteTimestamp(cmd_, VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, queries_, index);
  return index;
}

void Commands::submit() {
  if (context_.lost_) {
    if (recording_) {
      (void)vkEndCommandBuffer(cmd_);
      (void)vkResetCommandBuffer(cmd_, 0);
      recording_ = false;
    }
    throw GpuError("vkQueueSubmit", VK_ERROR_DEVICE_LOST);
  }
  begin_if_needed();
  check(vkEndCommandBuffer(cmd_), "vkEndCommandBuffer");
  recording_ = false;
  VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
  si.commandBufferCount = 1;
  si.pCommandBuffers = &cmd_;
  VkDevice d = context_.device();
  check(vkResetFences(d, 1, &fence_), "vkResetFences");
  VkResult r;
  {
    const std::unique_lock<std::mutex> lock = context_.lock_queue();
    context_.submits_.fetch_add(1, std::memory_order_relaxed);
    r = vkQueueSubmit(context_.queue(), 1, &si, fence_);
  }
  if (r == VK_SUCCESS) r = vkWaitForFences(d, 1, &fence_, VK_TRUE, UINT64_MAX);
  if (r == VK_ERROR_DEVICE_LOST) context_.lost_ = true;
  check(r, "vkQueueSubmit");
  const std::uint32_t n = std::min(timestamps_, max_timestamps_);
  results_.assign(n, 0);
  if (queries_ != VK_NULL_HANDLE && n > 0)
    check(vkGetQueryPoolResults(d, queries_, 0, n, n * sizeof(std::uint64_t), results_.data(),
                                sizeof(std::uint64_t),
                                VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT),
          "vkGetQueryPoolResults");
  check(vkResetCommandBuffer(cmd_, 0), "vkResetCommandBuffer");
  for (VkDescriptorPool p : full_pools_) vkDestroyDescriptorPool(d, p, nullptr);
  full_pools_.clear();
  check(vkResetDescriptorPool(d, pool_, 0), "vkResetDescriptorPool");
}

double Commands::elapsed_ms(std::uint32_t from, std::uint32_t to) const {
  if (from >= results_.size() || to >= results_.size()) return 0.0;
  return double(results_[to] - results_[from]) * context_.info().timestamp_period_ns * 1e-6;
}

} // namespace specula::gpu
