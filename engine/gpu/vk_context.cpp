#include "specula/gpu/vk_context.h"

#include "specula/core/error.h"
#include "specula/core/log.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <utility>

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
  // A compute queue with timestamps first, then any compute queue.
  for (std::uint32_t i = 0; i < count; ++i)
    if ((families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) && families[i].timestampValidBits > 0)
      return std::int32_t(i);
  for (std::uint32_t i = 0; i < count; ++i)
    if (families[i].queueFlags & VK_QUEUE_COMPUTE_BIT) return std::int32_t(i);
  return -1;
}

/// An instance for enumeration only (no layers), or VK_NULL_HANDLE with the reason.
VkInstance bare_instance(std::string& why) {
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
  if (const VkResult r = vkCreateInstance(&ici, nullptr, &ctx->instance_); r != VK_SUCCESS)
    throw UnavailableError(std::string("no Vulkan instance (") + result_name(r) +
                           "): is a Vulkan driver installed (mesa-vulkan-drivers)?");
  if (!extensions.empty()) {
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
  info.max_workgroup_count_x = props.properties.limits.maxComputeWorkGroupCount[0];

  const float priority = 1.0f;
  VkDeviceQueueCreateInfo qci{VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO};
  qci.queueFamilyIndex = ctx->family_;
  qci.queueCount = 1;
  qci.pQueuePriorities = &priority;
  VkPhysicalDeviceFeatures enable{};
  enable.shaderFloat64 = features.shaderFloat64;
  enable.shaderInt64 = features.shaderInt64;
  VkDeviceCreateInfo dci{VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO};
  dci.queueCreateInfoCount = 1;
  dci.pQueueCreateInfos = &qci;
  dci.pEnabledFeatures = &enable;
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
  bci.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT |
              VK_BUFFER_USAGE_TRANSFER_DST_BIT | VK_BUFFER_USAGE_INDIRECT_BUFFER_BIT;
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
  if (memory_.memoryTypes[type].propertyFlags & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT) {
    if (memory_.memoryTypes[type].propertyFlags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT)
      check(vkMapMemory(device_, b.memory_, 0, VK_WHOLE_SIZE, 0, &b.mapped_), "vkMapMemory");
  }
  return b;
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
  const VkResult r = vkQueueSubmit(queue_, 1, &si, VK_NULL_HANDLE);
  if (r == VK_ERROR_DEVICE_LOST) lost_ = true;
  check(r, "vkQueueSubmit");
  const VkResult w = vkQueueWaitIdle(queue_);
  if (w == VK_ERROR_DEVICE_LOST) lost_ = true;
  check(w, "vkQueueWaitIdle");
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
  }
  return *this;
}
void Buffer::release() noexcept {
  if (context_ == nullptr) return;
  VkDevice d = context_->device();
  if (buffer_ != VK_NULL_HANDLE) vkDestroyBuffer(d, buffer_, nullptr);
  if (memory_ != VK_NULL_HANDLE) vkFreeMemory(d, memory_, nullptr); // unmaps too
  buffer_ = VK_NULL_HANDLE;
  memory_ = VK_NULL_HANDLE;
  mapped_ = nullptr;
  context_ = nullptr;
}

void Buffer::upload(const void* data, VkDeviceSize bytes, VkDeviceSize offset) {
  if (bytes == 0) return;
  if (offset + bytes > size_)
    throw GpuError("Buffer::upload beyond the buffer's end", VK_ERROR_UNKNOWN);
  if (mapped_ != nullptr) {
    std::memcpy(static_cast<char*>(mapped_) + offset, data, bytes);
    return;
  }
  Buffer staging = context_->make_buffer(bytes, MemoryKind::host);
  std::memcpy(staging.mapped(), data, bytes);
  context_->run_now([&](VkCommandBuffer cmd) {
    const VkBufferCopy region{0, offset, bytes};
    vkCmdCopyBuffer(cmd, staging.handle(), buffer_, 1, &region);
  });
}

void Buffer::download(void* data, VkDeviceSize bytes, VkDeviceSize offset) const {
  if (bytes == 0) return;
  if (offset + bytes > size_)
    throw GpuError("Buffer::download beyond the buffer's end", VK_ERROR_UNKNOWN);
  if (mapped_ != nullptr) {
    std::memcpy(data, static_cast<const char*>(mapped_) + offset, bytes);
    return;
  }
  Buffer staging = context_->make_buffer(bytes, MemoryKind::host);
  context_->run_now([&](VkCommandBuffer cmd) {
    const VkBufferCopy region{offset, 0, bytes};
    vkCmdCopyBuffer(cmd, buffer_, staging.handle(), 1, &region);
  });
  std::memcpy(data, staging.mapped(), bytes);
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
    push_bytes_ = o.push_bytes_;
  }
  return *this;
}
void Pipeline::release() noexcept {
  if (context_ == nullptr) return;
  VkDevice d = context_->device();
  if (pipeline_ != VK_NULL_HANDLE) vkDestroyPipeline(d, pipeline_, nullptr);
  if (layout_ != VK_NULL_HANDLE) vkDestroyPipelineLayout(d, layout_, nullptr);
  if (set_layout_ != VK_NULL_HANDLE) vkDestroyDescriptorSetLayout(d, set_layout_, nullptr);
  if (module_ != VK_NULL_HANDLE) vkDestroyShaderModule(d, module_, nullptr);
  pipeline_ = VK_NULL_HANDLE;
  context_ = nullptr;
}

Pipeline Context::make_pipeline(const PipelineDesc& desc) {
  Pipeline p;
  p.context_ = this;
  p.bindings_ = desc.storage_buffers;
  p.push_bytes_ = desc.push_constant_bytes;
  VkShaderModuleCreateInfo smci{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  smci.codeSize = desc.spirv.size_bytes();
  smci.pCode = desc.spirv.data();
  check(vkCreateShaderModule(device_, &smci, nullptr, &p.module_), "vkCreateShaderModule");
  std::vector<VkDescriptorSetLayoutBinding> bindings(desc.storage_buffers);
  for (std::uint32_t i = 0; i < desc.storage_buffers; ++i)
    bindings[i] = {i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, nullptr};
  VkDescriptorSetLayoutCreateInfo dlci{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  dlci.bindingCount = desc.storage_buffers;
  dlci.pBindings = bindings.data();
  check(vkCreateDescriptorSetLayout(device_, &dlci, nullptr, &p.set_layout_),
        "vkCreateDescriptorSetLayout");
  VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, desc.push_constant_bytes};
  VkPipelineLayoutCreateInfo plci{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  plci.setLayoutCount = 1;
  plci.pSetLayouts = &p.set_layout_;
  plci.pushConstantRangeCount = desc.push_constant_bytes > 0 ? 1 : 0;
  plci.pPushConstantRanges = &range;
  check(vkCreatePipelineLayout(device_, &plci, nullptr, &p.layout_), "vkCreatePipelineLayout");
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
  const VkDescriptorPoolSize size{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1024};
  VkDescriptorPoolCreateInfo ci{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  ci.maxSets = 128;
  ci.poolSizeCount = 1;
  ci.pPoolSizes = &size;
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
void bind(VkDevice device, VkCommandBuffer cmd, VkDescriptorSet set, VkPipeline pipeline,
          VkPipelineLayout layout, std::span<const Buffer* const> buffers, const void* push,
          std::uint32_t push_bytes) {
  std::vector<VkDescriptorBufferInfo> infos(buffers.size());
  std::vector<VkWriteDescriptorSet> writes(buffers.size());
  for (std::size_t i = 0; i < buffers.size(); ++i) {
    infos[i] = {buffers[i]->handle(), 0, VK_WHOLE_SIZE};
    writes[i] = {VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
    writes[i].dstSet = set;
    writes[i].dstBinding = std::uint32_t(i);
    writes[i].descriptorCount = 1;
    writes[i].descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
    writes[i].pBufferInfo = &infos[i];
  }
  vkUpdateDescriptorSets(device, std::uint32_t(writes.size()), writes.data(), 0, nullptr);
  vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline);
  vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout, 0, 1, &set, 0, nullptr);
  if (push_bytes > 0 && push != nullptr)
    vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, push_bytes, push);
}
} // namespace

void Commands::dispatch(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                        const void* push_constants, std::uint32_t gx, std::uint32_t gy,
                        std::uint32_t gz) {
  if (buffers.size() != pipeline.bindings_)
    throw GpuError(std::string("dispatch: wrong buffer count for ") + "a pipeline",
                   VK_ERROR_UNKNOWN);
  begin_if_needed();
  const VkDescriptorSet set = allocate_set(pipeline);
  bind(context_.device(), cmd_, set, pipeline.pipeline_, pipeline.layout_, buffers, push_constants,
       pipeline.push_bytes_);
  if (gx > 0 && gy > 0 && gz > 0) vkCmdDispatch(cmd_, gx, gy, gz);
}

void Commands::dispatch_indirect(const Pipeline& pipeline, std::span<const Buffer* const> buffers,
                                 const void* push_constants, const Buffer& args,
                                 VkDeviceSize offset) {
  if (buffers.size() != pipeline.bindings_)
    throw GpuError("dispatch_indirect: wrong buffer count", VK_ERROR_UNKNOWN);
  begin_if_needed();
  const VkDescriptorSet set = allocate_set(pipeline);
  bind(context_.device(), cmd_, set, pipeline.pipeline_, pipeline.layout_, buffers, push_constants,
       pipeline.push_bytes_);
  vkCmdDispatchIndirect(cmd_, args.handle(), offset);
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
  VkResult r = vkQueueSubmit(context_.queue(), 1, &si, fence_);
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
