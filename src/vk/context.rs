//! The Vulkan context: instance, validation messenger, device, queue and
//! allocator. Everything GPU-side in pointlens goes through one `Context`.

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::frame::{FrameObjects, KEPT_FRAMES};
use super::pool::{Key, Parts, Pool};

use crate::error::{Error, Result, VkContext};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// How to create a [`Context`].
#[derive(Debug, Clone, Default)]
pub struct ContextOptions {
    /// Enable `VK_LAYER_KHRONOS_validation` with synchronization validation.
    pub validation: bool,
    /// Pick the device at this place in the loader's list (a number, as
    /// `--list-devices` numbers them), or the first whose name or driver
    /// name contains this (case-insensitive); otherwise discrete >
    /// integrated > virtual > CPU.
    pub device: Option<String>,
}

impl ContextOptions {
    /// Validation from `--validate` or the `POINTLENS_VALIDATION=1` environment variable.
    pub fn from_env(validate_flag: bool, device: Option<String>) -> Self {
        let env = std::env::var("POINTLENS_VALIDATION").is_ok_and(|v| v == "1");
        ContextOptions {
            validation: validate_flag || env,
            device,
        }
    }
}

/// One message from the validation layer (or the loader) at warning or error severity.
#[derive(Debug, Clone)]
pub struct ValidationMessage {
    pub severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    pub id_name: String,
    pub text: String,
}

impl std::fmt::Display for ValidationMessage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sev = if self.severity == vk::DebugUtilsMessageSeverityFlagsEXT::ERROR {
            "error"
        } else {
            "warning"
        };
        write!(f, "validation {sev}: [{}] {}", self.id_name, self.text)
    }
}

/// A shared handle on the validation messages of a [`Context`].
#[derive(Clone)]
pub struct MessageLog(Arc<Mutex<Vec<ValidationMessage>>>);

impl MessageLog {
    /// The messages recorded so far.
    pub fn messages(&self) -> Vec<ValidationMessage> {
        self.0.lock().map(|v| v.clone()).unwrap_or_default()
    }
}

/// What the program reports about the device it runs on.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    /// Its place in the loader's list of devices (`--list-devices`, `--device N`).
    pub index: u32,
    pub name: String,
    pub driver_name: String,
    pub driver_info: String,
    /// The driver's own version number (vendor-specific encoding).
    pub driver_version: u32,
    pub device_type: vk::PhysicalDeviceType,
    pub api_version: u32,
    pub max_image_dimension_2d: u32,
    pub point_size_max: f32,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f32,
    pub timestamp_valid_bits: u32,
    /// Size of the largest device-local heap, bytes.
    pub device_local_heap_bytes: u64,
    /// The largest single allocation the driver promises, bytes.
    pub max_memory_allocation_bytes: u64,
    pub max_image_array_layers: u32,
    /// Sample counts a multisampled G-buffer can use: color (rgba16f,
    /// rgba32f) and depth (D32) attachments that compute reads as storage
    /// images, at the standard sample locations. Only `TYPE_1` where the
    /// device lacks `shaderStorageImageMultisample` or standard locations.
    pub gbuffer_sample_counts: vk::SampleCountFlags,
    /// 64-bit integer atomics on storage buffers (`shaderInt64` and
    /// `shaderBufferInt64Atomics`), enabled when present.
    pub buffer_int64_atomics: bool,
    /// Whether fragment shaders may run once per sample
    /// (`sampleRateShading`): the disc splats' sprites need it.
    pub sample_rate_shading: bool,
    /// The largest storage-buffer binding, bytes.
    pub max_storage_buffer_range: u64,
    /// Invocations of a subgroup (8 on lavapipe, 32 on NVIDIA, 32 or 64 on
    /// AMD).
    pub subgroup_size: u32,
    /// The most invocations of a compute workgroup.
    pub max_compute_workgroup_invocations: u32,
}

/// The loop iterations a shader invocation runs on llvmpipe, all its loops
/// together: Mesa's `LP_MAX_TGSI_LOOP_ITERATIONS`. Past it the loops stop
/// without a word (docs/ARCHITECTURE.md, "llvmpipe's loop limit").
pub const LLVMPIPE_LOOP_ITERATIONS: u64 = 65_535;

impl DeviceInfo {
    /// `name (driver driver_info)`, for reports.
    pub fn describe(&self) -> String {
        format!("{} ({} {})", self.name, self.driver_name, self.driver_info)
    }

    /// The largest buffer one storage-buffer binding holds and one
    /// allocation can make.
    pub fn largest_storage_buffer_bytes(&self) -> u64 {
        self.max_storage_buffer_range
            .min(self.max_memory_allocation_bytes)
    }

    /// The most loop iterations a shader invocation runs, where the driver
    /// has such a limit (llvmpipe); None elsewhere.
    pub fn loop_iterations_limit(&self) -> Option<u64> {
        let llvmpipe = self.name.starts_with("llvmpipe") || self.driver_name == "llvmpipe";
        llvmpipe.then_some(LLVMPIPE_LOOP_ITERATIONS)
    }
}

struct Messenger {
    loader: ash::ext::debug_utils::Instance,
    raw: vk::DebugUtilsMessengerEXT,
    /// Kept alive here; the callback gets a raw pointer to the mutex as user data.
    _sink: Arc<Mutex<Vec<ValidationMessage>>>,
}

/// Instance, device, queue and allocator. Create one with [`Context::new`]
/// and share it as `Arc<Context>`; every GPU resource holds a clone, so the
/// context is destroyed last.
pub struct Context {
    _entry: ash::Entry,
    pub(super) instance: ash::Instance,
    messenger: Option<Messenger>,
    messages: Arc<Mutex<Vec<ValidationMessage>>>,
    pub(super) device: ash::Device,
    debug_utils: ash::ext::debug_utils::Device,
    pub(super) push_descriptor: ash::khr::push_descriptor::Device,
    pub(super) queue: vk::Queue,
    /// Held while submitting to `queue` (Vulkan requires it externally
    /// synchronised; the context is shared between threads). It holds the
    /// fence of the flush that follows each frame under the validation
    /// layer ([`Context::queue_lock`]; null without validation).
    queue_submit: Mutex<vk::Fence>,
    pub(super) queue_family: u32,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    /// The last frames' dropped images and buffers, for the next frame.
    pool: Mutex<Pool>,
    /// Completed frames' command pools, fences and timestamp pools, for
    /// the next frames ([`super::frame::FrameObjects`]).
    frames: Mutex<KeptFrames>,
    pub info: DeviceInfo,
    validation: bool,
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: `user` points to the mutex kept alive by `Messenger::_sink` (and
    // `Context::messages`), which outlive the messenger objects; `data` is
    // valid for the call's duration.
    unsafe {
        let sink = &*(user as *const Mutex<Vec<ValidationMessage>>);
        let data = &*data;
        let cstr = |p: *const std::ffi::c_char| {
            if p.is_null() {
                String::new()
            } else {
                CStr::from_ptr(p).to_string_lossy().into_owned()
            }
        };
        let msg = ValidationMessage {
            severity,
            id_name: cstr(data.p_message_id_name),
            text: cstr(data.p_message),
        };
        eprintln!("{msg}");
        if let Ok(mut v) = sink.lock() {
            v.push(msg);
        }
    }
    vk::FALSE
}

const INSTALL_HINT: &str = "install Vulkan with: apt-get install libvulkan1 mesa-vulkan-drivers \
                            vulkan-validationlayers";

impl Context {
    /// Creates the instance (Vulkan 1.3), the validation messenger when asked
    /// for, picks a device and creates it with dynamic rendering,
    /// synchronization2, maintenance4, large points and push descriptors.
    pub fn new(options: &ContextOptions) -> Result<Arc<Context>> {
        // SAFETY: loading the system Vulkan loader; it stays loaded as long as
        // `_entry`, which the context owns and drops last.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| {
            Error::VulkanSetup(format!(
                "cannot load the Vulkan loader ({e}); {INSTALL_HINT}"
            ))
        })?;

        // SAFETY: plain queries on a valid entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .vk("vkEnumerateInstanceLayerProperties")?;
        if options.validation
            && !layers
                .iter()
                .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER))
        {
            return Err(Error::VulkanSetup(format!(
                "validation requested but {} is not installed; {INSTALL_HINT}",
                VALIDATION_LAYER.to_string_lossy()
            )));
        }
        // SAFETY: as above.
        let instance_exts = unsafe { entry.enumerate_instance_extension_properties(None) }
            .vk("vkEnumerateInstanceExtensionProperties")?;
        let has_debug_utils = instance_exts
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::debug_utils::NAME));
        if !has_debug_utils {
            return Err(Error::VulkanSetup(format!(
                "the Vulkan loader lacks VK_EXT_debug_utils; {INSTALL_HINT}"
            )));
        }

        let app_info = vk::ApplicationInfo::default()
            .application_name(c"pointlens")
            .application_version(1)
            .engine_name(c"pointlens")
            .api_version(vk::API_VERSION_1_3);
        let layer_ptrs = if options.validation {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            vec![]
        };
        let ext_ptrs = [ash::ext::debug_utils::NAME.as_ptr()];
        let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut validation_features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);

        let messages = Arc::new(Mutex::new(Vec::new()));
        let sink = messages.clone();
        let user_data = Arc::as_ptr(&sink) as *mut c_void;
        // One for instance creation and destruction (chained), one for the
        // messenger object: the latter must have no pNext.
        let mut instance_messenger_info = messenger_create_info(user_data);
        let messenger_info = messenger_create_info(user_data);

        let mut create_info = vk::InstanceCreateInfo::default()
            .application_info(&app_info)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        if options.validation {
            // Chained so that instance creation itself is also validated.
            create_info = create_info
                .push_next(&mut validation_features)
                .push_next(&mut instance_messenger_info);
        }
        // SAFETY: every pointer in `create_info` refers to locals alive here.
        let instance = unsafe { entry.create_instance(&create_info, None) }.map_err(|e| {
            Error::VulkanSetup(format!(
                "vkCreateInstance failed ({e}): no Vulkan 1.3 driver? {INSTALL_HINT}"
            ))
        })?;

        // From here on, a failure must destroy what was created: build a
        // partial context step by step through `Partial`.
        let mut partial = Partial {
            instance: Some(instance),
            messenger: None,
        };
        if options.validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, partial.instance());
            // SAFETY: valid instance; `sink` is moved into the Messenger and
            // so outlives the messenger object.
            let raw = unsafe { loader.create_debug_utils_messenger(&messenger_info, None) }
                .vk("vkCreateDebugUtilsMessengerEXT")?;
            partial.messenger = Some(Messenger {
                loader,
                raw,
                _sink: sink,
            });
        }

        let (physical_device, queue_family, info) =
            pick_device(partial.instance(), options.device.as_deref())?;

        let queue_priorities = [1.0f32];
        let queue_infos = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family)
            .queue_priorities(&queue_priorities)];
        let device_exts = [ash::khr::push_descriptor::NAME.as_ptr()];
        let multisampled_storage = info.gbuffer_sample_counts != vk::SampleCountFlags::TYPE_1;
        let features = vk::PhysicalDeviceFeatures::default()
            .large_points(true)
            .shader_storage_image_multisample(multisampled_storage)
            .shader_int64(info.buffer_int64_atomics)
            .sample_rate_shading(info.sample_rate_shading);
        let mut features12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_buffer_int64_atomics(info.buffer_int64_atomics);
        let mut features13 = vk::PhysicalDeviceVulkan13Features::default()
            .dynamic_rendering(true)
            // Required of every Vulkan 1.3 device; `discard` in the depth
            // peel compiles to OpDemoteToHelperInvocation for SPIR-V 1.6.
            .shader_demote_to_helper_invocation(true)
            .synchronization2(true)
            .maintenance4(true);
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_infos)
            .enabled_extension_names(&device_exts)
            .enabled_features(&features)
            .push_next(&mut features12)
            .push_next(&mut features13);
        // SAFETY: physical device from this instance; pointers are locals.
        let device = unsafe {
            partial
                .instance()
                .create_device(physical_device, &device_info, None)
        }
        .vk("vkCreateDevice")?;
        // SAFETY: the queue family and index 0 were requested above.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };

        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: partial.instance().clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        });
        let allocator = match allocator {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: nothing was created from the device yet.
                unsafe { device.destroy_device(None) };
                return Err(Error::Allocation(e.to_string()));
            }
        };

        let debug_utils = ash::ext::debug_utils::Device::new(partial.instance(), &device);
        let push_descriptor = ash::khr::push_descriptor::Device::new(partial.instance(), &device);
        let (instance, messenger) = partial.take();
        let mut ctx = Context {
            _entry: entry,
            instance,
            messenger,
            messages,
            device,
            debug_utils,
            push_descriptor,
            queue,
            queue_submit: Mutex::new(vk::Fence::null()),
            queue_family,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            pool: Mutex::new(Pool::default()),
            frames: Mutex::new(KeptFrames::default()),
            info,
            validation: options.validation,
        };
        ctx.set_name(ctx.queue, "main queue");
        if ctx.validation {
            // SAFETY: plain object creation on this device; the context
            // owns the fence from here on, and its Drop destroys it.
            let fence = unsafe {
                ctx.device
                    .create_fence(&vk::FenceCreateInfo::default(), None)
            }
            .vk("vkCreateFence")?;
            *ctx.queue_submit
                .get_mut()
                .unwrap_or_else(|p| p.into_inner()) = fence;
            ctx.set_name(fence, "frame flush");
        }
        Ok(Arc::new(ctx))
    }

    /// The lock held while submitting to the queue, with the fence of the
    /// flush that follows a frame under the validation layer (null
    /// without): [`super::Frame::submit_and_wait`] submits nothing with it
    /// and waits, so that the layer's own threads have let go of the
    /// frame's command buffer before its pool is destroyed (the layer of
    /// Debian 12, 1.3.239, can otherwise destroy a command buffer's state
    /// on its thread while this one records labels: the race of
    /// `tests/label_race.rs`, docs/bench/history/heap-at-exit.md).
    pub(super) fn queue_lock(&self) -> MutexGuard<'_, vk::Fence> {
        self.queue_submit
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Makes one invalid Vulkan call (a buffer of size 0) so that a test
    /// can check that the validation canary sees messages.
    ///
    /// # Safety
    /// The call breaks a valid-usage rule (VUID-VkBufferCreateInfo-size-00912)
    /// on purpose: only for tests, with the validation layer on, on a driver
    /// known to tolerate it (lavapipe returns an error or a buffer that is
    /// destroyed at once).
    #[doc(hidden)]
    pub unsafe fn provoke_validation_message(&self) {
        let info = vk::BufferCreateInfo::default()
            .size(0)
            .usage(vk::BufferUsageFlags::STORAGE_BUFFER);
        // SAFETY: deliberately invalid create info (size 0,
        // VUID-VkBufferCreateInfo-size-00912) that drivers tolerate; a
        // buffer it returns is unused and destroyed at once.
        unsafe {
            if let Ok(b) = self.device.create_buffer(&info, None) {
                self.device.destroy_buffer(b, None);
            }
        }
    }

    /// Fails when the validation layer reported anything so far (each
    /// message was printed to stderr as it came): with validation on, any
    /// message fails `render`, `bench` and the tests alike.
    pub fn check_validation(&self) -> Result<()> {
        match self.validation_messages().len() {
            0 => Ok(()),
            n => Err(Error::Validation(n)),
        }
    }

    /// Whether the validation layer is on.
    pub fn validation_enabled(&self) -> bool {
        self.validation
    }

    /// Every validation warning and error recorded so far.
    pub fn validation_messages(&self) -> Vec<ValidationMessage> {
        self.message_log().messages()
    }

    /// A handle on the message record that outlives the context, so that
    /// messages emitted while the device is destroyed are seen too.
    pub fn message_log(&self) -> MessageLog {
        MessageLog(self.messages.clone())
    }

    /// The allocator, locked.
    pub(crate) fn allocator(&self) -> MutexGuard<'_, Allocator> {
        // A poisoned lock only means another thread panicked mid-allocation;
        // the allocator's own state is still consistent.
        self.allocator
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The pool of dropped images and buffers, locked.
    pub(super) fn pool(&self) -> MutexGuard<'_, Pool> {
        self.pool
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Destroys the objects of a pooled image or buffer and frees its memory.
    pub(super) fn destroy(&self, parts: Parts) {
        match parts {
            Parts::Image {
                raw,
                view,
                allocation,
            } => {
                // SAFETY: pooled objects are unused: they were dropped after
                // the GPU finished with them (see `Image`'s drop), and the
                // pool gave them to no one. View before image before memory.
                unsafe {
                    self.device.destroy_image_view(view, None);
                    self.device.destroy_image(raw, None);
                }
                let _ = self.allocator().free(allocation);
            }
            Parts::Buffer { raw, allocation } => {
                // SAFETY: as for images above.
                unsafe { self.device.destroy_buffer(raw, None) };
                let _ = self.allocator().free(allocation);
            }
        }
    }

    /// Takes the objects of a dropped image or buffer: into the pool when
    /// it was made completely (and the pool is on), else destroyed.
    pub(super) fn recycle(&self, key: &Key, parts: Parts, complete: bool) {
        let unpooled = match complete {
            true => self.pool().give(key.clone(), parts),
            false => Some(parts),
        };
        if let Some(parts) = unpooled {
            self.destroy(parts);
        }
    }

    /// Starts a frame: frees the pooled images and buffers that neither of
    /// the last two frames took (see `vk::pool`). Call before allocating a
    /// frame's resources.
    pub fn next_frame(&self) {
        let stale = self.pool().next_frame();
        for parts in stale {
            self.destroy(parts);
        }
    }

    /// Frees every pooled image and buffer (they are kept for the next
    /// frame otherwise).
    pub fn release_pool(&self) {
        let all = self.pool().drain();
        for parts in all {
            self.destroy(parts);
        }
    }

    /// Turns the recycling of images, buffers and frames' command pools,
    /// fences and timestamp pools between frames on (the default) or off
    /// (every frame makes its own and destroys them after: for measuring
    /// what the recycling saves).
    pub fn set_frame_pool(&self, on: bool) {
        self.pool().disabled = !on;
        if !on {
            self.release_pool();
            self.release_frame_objects();
        }
    }

    /// A completed frame's objects for the next frame, if one is kept.
    pub(super) fn take_frame_objects(&self) -> Option<FrameObjects> {
        let mut kept = self.kept_frames();
        match kept.objects.pop() {
            Some(objects) => {
                kept.reused += 1;
                Some(objects)
            }
            None => {
                kept.created += 1;
                None
            }
        }
    }

    /// Keeps a completed frame's objects (reset) for the next frame; they
    /// are destroyed instead when the pool is off or enough are kept.
    pub(super) fn keep_frame_objects(&self, objects: FrameObjects) {
        let unkept = {
            let mut kept = self.kept_frames();
            if self.pool().disabled || kept.objects.len() >= KEPT_FRAMES {
                Some(objects)
            } else {
                kept.objects.push(objects);
                None
            }
        };
        if let Some(objects) = unkept {
            // SAFETY: a completed frame's objects, in no pending submission.
            unsafe { objects.destroy(&self.device) };
        }
    }

    /// Destroys the kept frames' objects.
    fn release_frame_objects(&self) {
        let all = std::mem::take(&mut self.kept_frames().objects);
        for objects in all {
            // SAFETY: kept objects are those of completed frames.
            unsafe { objects.destroy(&self.device) };
        }
    }

    fn kept_frames(&self) -> MutexGuard<'_, KeptFrames> {
        self.frames
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Frames' objects: (sets made anew, sets taken from an earlier
    /// frame), for tests and reports.
    pub fn frame_object_counts(&self) -> (u64, u64) {
        let kept = self.kept_frames();
        (kept.created, kept.reused)
    }

    /// The pool's counts: (objects created anew, objects reused, objects
    /// pooled now), for tests and reports.
    pub fn pool_counts(&self) -> (u64, u64, usize) {
        let pool = self.pool();
        (pool.created, pool.reused, pool.len())
    }

    /// Bytes of device memory allocated now (pooled objects included).
    pub fn allocated_bytes(&self) -> u64 {
        self.allocator().generate_report().total_allocated_bytes
    }

    /// Names of the allocations still alive (empty when every resource was
    /// freed), after freeing the pool.
    pub fn live_allocations(&self) -> Vec<String> {
        self.release_pool();
        self.allocator()
            .generate_report()
            .allocations
            .iter()
            .map(|a| format!("{} ({} bytes)", a.name, a.size))
            .collect()
    }

    /// Gives a Vulkan object a debug name (shown by validation messages and tools).
    pub(super) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Ok(name) = CString::new(name) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: the handle belongs to this device; naming never fails in a
        // way that matters, so the result is ignored.
        let _ = unsafe { self.debug_utils.set_debug_utils_object_name(&info) };
    }

    /// Opens a debug label region in a command buffer.
    pub(crate) fn begin_label(&self, cmd: vk::CommandBuffer, name: &str) {
        let name = CString::new(name).unwrap_or_default();
        let label = vk::DebugUtilsLabelEXT::default().label_name(&name);
        // SAFETY: `cmd` is in the recording state.
        unsafe { self.debug_utils.cmd_begin_debug_utils_label(cmd, &label) };
    }

    /// Closes the innermost debug label region.
    pub(crate) fn end_label(&self, cmd: vk::CommandBuffer) {
        // SAFETY: paired with `begin_label` on the same recording buffer.
        unsafe { self.debug_utils.cmd_end_debug_utils_label(cmd) };
    }
}

/// Completed frames' objects and how often a frame made or took them.
#[derive(Default)]
struct KeptFrames {
    objects: Vec<FrameObjects>,
    created: u64,
    reused: u64,
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: every resource holds an `Arc<Context>`, so none is alive
        // now. Teardown in reverse creation order: allocator, device,
        // messenger, instance.
        unsafe {
            let _ = self.device.device_wait_idle();
        }
        self.release_pool();
        self.release_frame_objects();
        let flush = *self
            .queue_submit
            .get_mut()
            .unwrap_or_else(|p| p.into_inner());
        // SAFETY: as above; the pool is empty now, and the flush fence is
        // not in use (the device is idle; a null one is ignored).
        unsafe {
            self.device.destroy_fence(flush, None);
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some(m) = self.messenger.take() {
                m.loader.destroy_debug_utils_messenger(m.raw, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// Owns the instance and messenger until the context takes them, so an
/// error in between destroys them.
struct Partial {
    instance: Option<ash::Instance>,
    messenger: Option<Messenger>,
}

impl Partial {
    fn instance(&self) -> &ash::Instance {
        self.instance
            .as_ref()
            .expect("instance taken only by take()")
    }
    fn take(mut self) -> (ash::Instance, Option<Messenger>) {
        let i = self.instance.take().expect("take() called once");
        (i, self.messenger.take())
    }
}

impl Drop for Partial {
    fn drop(&mut self) {
        // SAFETY: only reached on an error path, before any device exists.
        unsafe {
            if let Some(m) = self.messenger.take() {
                m.loader.destroy_debug_utils_messenger(m.raw, None);
            }
            if let Some(i) = self.instance.take() {
                i.destroy_instance(None);
            }
        }
    }
}

fn messenger_create_info(user_data: *mut c_void) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(user_data)
}

fn type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

/// The sample counts of [`DeviceInfo::gbuffer_sample_counts`].
fn gbuffer_sample_counts(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    props: &vk::PhysicalDeviceProperties,
) -> vk::SampleCountFlags {
    // SAFETY: `pd` comes from this instance; a plain query.
    let features = unsafe { instance.get_physical_device_features(pd) };
    if features.shader_storage_image_multisample == vk::FALSE
        || props.limits.standard_sample_locations == vk::FALSE
    {
        return vk::SampleCountFlags::TYPE_1;
    }
    let limits = &props.limits;
    let mut counts = limits.framebuffer_color_sample_counts
        & limits.framebuffer_depth_sample_counts
        & limits.storage_image_sample_counts;
    let color = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE;
    for (format, usage) in [
        (vk::Format::R16G16B16A16_SFLOAT, color),
        (vk::Format::R32G32B32A32_SFLOAT, color),
        (
            vk::Format::D32_SFLOAT,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
        ),
    ] {
        // SAFETY: as above.
        let supported = unsafe {
            instance.get_physical_device_image_format_properties(
                pd,
                format,
                vk::ImageType::TYPE_2D,
                vk::ImageTiling::OPTIMAL,
                usage,
                vk::ImageCreateFlags::empty(),
            )
        };
        counts &= supported.map_or(vk::SampleCountFlags::TYPE_1, |p| p.sample_counts);
    }
    counts | vk::SampleCountFlags::TYPE_1
}

/// A fault to inject for tests of the error paths: the environment
/// variable `POINTLENS_INJECT_FAULT=CALL=RESULT` (e.g.
/// `vkQueueSubmit=ERROR_DEVICE_LOST`, `vkWaitForFences=ERROR_DEVICE_LOST`
/// (after the real wait), `vkAllocateMemory=ERROR_OUT_OF_DEVICE_MEMORY`,
/// or `vkAllocateMemory@gbuffer color=…` for one resource's memory) makes
/// that call fail with that result instead of being made. Read once.
pub(crate) fn injected_fault(call: &str) -> Option<vk::Result> {
    static FAULT: std::sync::OnceLock<Option<(String, vk::Result)>> = std::sync::OnceLock::new();
    let fault = FAULT.get_or_init(|| {
        let text = std::env::var("POINTLENS_INJECT_FAULT").ok()?;
        let (name, result) = text.split_once('=')?;
        let result = match result {
            "ERROR_DEVICE_LOST" => vk::Result::ERROR_DEVICE_LOST,
            "ERROR_OUT_OF_DEVICE_MEMORY" => vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
            "ERROR_OUT_OF_HOST_MEMORY" => vk::Result::ERROR_OUT_OF_HOST_MEMORY,
            _ => return None,
        };
        Some((name.to_string(), result))
    });
    match fault {
        Some((name, result)) if name == call => Some(*result),
        _ => None,
    }
}

/// One Vulkan device as `--list-devices` shows it.
#[derive(Debug, Clone)]
pub struct DeviceListing {
    /// Its place in the loader's list, what `--device N` takes.
    pub index: u32,
    /// `name (driver driver_info)`.
    pub description: String,
    /// `discrete GPU`, `integrated GPU`, `CPU`, …
    pub kind: String,
    /// Vulkan version, `1.3.230`.
    pub api_version: String,
    /// The largest device-local heap, bytes.
    pub heap_bytes: u64,
    /// Why pointlens cannot use it, if it cannot.
    pub unusable: Option<String>,
    /// Whether pointlens picks it when no `--device` is given.
    pub default: bool,
}

impl Context {
    /// Every Vulkan device the loader reports, with the one pointlens picks
    /// by default marked (`--list-devices`).
    pub fn list_devices() -> Result<Vec<DeviceListing>> {
        // SAFETY: as in `Context::new`: the entry outlives the instance,
        // destroyed before returning.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| {
            Error::VulkanSetup(format!(
                "cannot load the Vulkan loader ({e}); {INSTALL_HINT}"
            ))
        })?;
        let app_info = vk::ApplicationInfo::default()
            .application_name(c"pointlens")
            .api_version(vk::API_VERSION_1_3);
        let info = vk::InstanceCreateInfo::default().application_info(&app_info);
        // SAFETY: valid create info of locals.
        let instance = unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?;
        let listed = list_with(&instance);
        // SAFETY: nothing was created from the instance but queries.
        unsafe { instance.destroy_instance(None) };
        listed
    }
}

/// The size of the largest device-local memory heap of `pd`, bytes.
fn largest_local_heap(instance: &ash::Instance, pd: vk::PhysicalDevice) -> u64 {
    // SAFETY: `pd` comes from this instance; a plain read.
    let mem = unsafe { instance.get_physical_device_memory_properties(pd) };
    mem.memory_heaps[..mem.memory_heap_count as usize]
        .iter()
        .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .map(|h| h.size)
        .max()
        .unwrap_or(0)
}

fn list_with(instance: &ash::Instance) -> Result<Vec<DeviceListing>> {
    let chosen = pick_device(instance, None)
        .ok()
        .map(|(_, _, info)| info.index);
    // SAFETY: valid instance; plain reads.
    let devices =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    let mut out = Vec::new();
    for (index, pd) in (0u32..).zip(devices) {
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut driver);
        // SAFETY: `pd` comes from this instance; one core 1.1 struct chained.
        unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
        let props = props2.properties;
        let text = |s: std::result::Result<&CStr, _>| {
            s.map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        let name = text(props.device_name_as_c_str());
        let heap_bytes = largest_local_heap(instance, pd);
        let v = props.api_version;
        out.push(DeviceListing {
            index,
            description: format!(
                "{name} ({} {})",
                text(driver.driver_name_as_c_str()),
                text(driver.driver_info_as_c_str())
            ),
            kind: match props.device_type {
                vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
                vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
                vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
                vk::PhysicalDeviceType::CPU => "CPU",
                _ => "other",
            }
            .to_string(),
            api_version: format!(
                "{}.{}.{}",
                vk::api_version_major(v),
                vk::api_version_minor(v),
                vk::api_version_patch(v)
            ),
            heap_bytes,
            unusable: (v < vk::API_VERSION_1_3).then(|| "needs Vulkan 1.3".to_string()),
            default: chosen == Some(index),
        });
    }
    Ok(out)
}

fn pick_device(
    instance: &ash::Instance,
    wanted: Option<&str>,
) -> Result<(vk::PhysicalDevice, u32, DeviceInfo)> {
    // SAFETY: valid instance; all queries below are plain reads.
    let devices =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    let mut candidates = Vec::new();
    let mut seen = Vec::new();
    // `--device 1`: the second device in the loader's list; any other text
    // is a part of a name.
    let wanted_index = wanted.and_then(|w| w.trim().parse::<u32>().ok());
    for (index, pd) in (0u32..).zip(devices) {
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut driver)
            .push_next(&mut maintenance3)
            .push_next(&mut subgroup);
        // SAFETY: `pd` comes from this instance; `props2` chains only
        // `driver`, `maintenance3` and `subgroup`, all core in Vulkan 1.1.
        unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
        let props = props2.properties;
        let name = props
            .device_name_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let driver_name = driver
            .driver_name_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let driver_info = driver
            .driver_info_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        seen.push(format!("{index}: {name}"));
        if props.api_version < vk::API_VERSION_1_3 {
            continue;
        }
        if let Some(i) = wanted_index {
            if i != index {
                continue;
            }
        } else if let Some(w) = wanted {
            let w = w.to_lowercase();
            if !name.to_lowercase().contains(&w) && !driver_name.to_lowercase().contains(&w) {
                continue;
            }
        }
        // SAFETY: plain queries on a physical device of this instance.
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        let Some((family, fprops)) = families.iter().enumerate().find(|(_, f)| {
            f.queue_flags
                .contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
        }) else {
            continue;
        };
        let device_local_heap_bytes = largest_local_heap(instance, pd);
        let gbuffer_sample_counts = gbuffer_sample_counts(instance, pd, &props);
        let mut features12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut features2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut features12);
        // SAFETY: as above; `features2` chains only the Vulkan 1.2 features,
        // core in the 1.3 devices kept here.
        unsafe { instance.get_physical_device_features2(pd, &mut features2) };
        let core = features2.features;
        let buffer_int64_atomics =
            core.shader_int64 == vk::TRUE && features12.shader_buffer_int64_atomics == vk::TRUE;
        let sample_rate_shading = core.sample_rate_shading == vk::TRUE;
        let info = DeviceInfo {
            index,
            name,
            driver_name,
            driver_info,
            driver_version: props.driver_version,
            device_type: props.device_type,
            api_version: props.api_version,
            max_image_dimension_2d: props.limits.max_image_dimension2_d,
            point_size_max: props.limits.point_size_range[1],
            timestamp_period_ns: props.limits.timestamp_period,
            timestamp_valid_bits: fprops.timestamp_valid_bits,
            device_local_heap_bytes,
            max_memory_allocation_bytes: maintenance3.max_memory_allocation_size,
            max_image_array_layers: props.limits.max_image_array_layers,
            gbuffer_sample_counts,
            buffer_int64_atomics,
            sample_rate_shading,
            max_storage_buffer_range: props.limits.max_storage_buffer_range as u64,
            subgroup_size: subgroup.subgroup_size,
            max_compute_workgroup_invocations: props.limits.max_compute_work_group_invocations,
        };
        candidates.push((pd, family as u32, info));
    }
    candidates.sort_by_key(|(_, _, info)| type_rank(info.device_type));
    candidates.into_iter().next().ok_or_else(|| {
        let list = if seen.is_empty() {
            "none".to_string()
        } else {
            seen.join(", ")
        };
        match wanted {
            Some(w) => Error::VulkanSetup(format!(
                "no Vulkan 1.3 device matches '{w}' (devices: {list}); {INSTALL_HINT}"
            )),
            None => Error::VulkanSetup(format!(
                "no Vulkan 1.3 device with graphics and compute (devices: {list}); {INSTALL_HINT}"
            )),
        }
    })
}
