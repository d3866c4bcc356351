//! Buffers and images that free themselves: each holds an `Arc<Context>`,
//! its allocation, and destroys its objects in reverse creation order.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::pool::{Key, Parts};
use super::Context;
use crate::error::{Error, Result, VkContext};

/// A buffer with its memory.
pub struct Buffer {
    ctx: Arc<Context>,
    pub(super) raw: vk::Buffer,
    size: u64,
    allocation: Option<Allocation>,
    /// What it was made with: where it goes back to the pool.
    key: Key,
    /// Made completely (bound, viewed): may go back to the pool.
    complete: bool,
}

impl Buffer {
    /// Creates a buffer of `size` bytes in `location` (use `CpuToGpu` /
    /// `GpuToCpu` for host-visible staging and readback buffers).
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Buffer> {
        let key = Key::Buffer {
            name: name.to_owned(),
            size,
            usage,
            location: location.into(),
        };
        let pooled = ctx.pool().take(&key);
        if let Some(Parts::Buffer { raw, allocation }) = pooled {
            return Ok(Buffer {
                ctx: ctx.clone(),
                raw,
                size,
                allocation: Some(allocation),
                key,
                complete: true,
            });
        }
        ctx.pool().created += 1;
        let info = vk::BufferCreateInfo::default()
            .size(size.max(4))
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid device and create info.
        let raw = unsafe { ctx.device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
        // SAFETY: `raw` was just created on this device.
        let requirements = unsafe { ctx.device.get_buffer_memory_requirements(raw) };
        let allocation = allocate(
            ctx,
            &AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            },
        );
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: the buffer is unused and unbound.
                unsafe { ctx.device.destroy_buffer(raw, None) };
                return Err(allocation_error(name, size, &e));
            }
        };
        let mut buffer = Buffer {
            ctx: ctx.clone(),
            raw,
            size,
            allocation: Some(allocation),
            key,
            complete: false,
        };
        let a = buffer.allocation.as_ref().expect("just set");
        // SAFETY: the allocation satisfies the buffer's requirements; bound once.
        unsafe {
            ctx.device
                .bind_buffer_memory(raw, a.memory(), a.offset())
                .vk("vkBindBufferMemory")?
        };
        ctx.set_name(raw, name);
        buffer.complete = true;
        Ok(buffer)
    }

    /// Creates a host-visible (`CpuToGpu`) buffer holding `bytes`: a table
    /// a shader reads, or a staging buffer.
    pub fn with_bytes(
        ctx: &Arc<Context>,
        name: &str,
        bytes: &[u8],
        usage: vk::BufferUsageFlags,
    ) -> Result<Buffer> {
        let mut buffer = Buffer::new(
            ctx,
            name,
            bytes.len() as u64,
            usage,
            MemoryLocation::CpuToGpu,
        )?;
        let mapped = buffer
            .mapped_mut()
            .ok_or_else(|| Error::Allocation(format!("{name} is not host-visible")))?;
        crate::copy_in_parallel(&[bytes], mapped, crate::available_threads());
        Ok(buffer)
    }

    /// Size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// Whether the buffer was made on `ctx`.
    pub fn made_on(&self, ctx: &Context) -> bool {
        std::ptr::eq(&*self.ctx, ctx)
    }

    /// Whether the buffer's memory is device-local: on a discrete GPU a
    /// host-visible buffer usually is not (system memory across the bus),
    /// on lavapipe and other unified-memory devices every buffer is.
    pub fn device_local(&self) -> bool {
        self.allocation.as_ref().is_some_and(|a| {
            a.memory_properties()
                .contains(vk::MemoryPropertyFlags::DEVICE_LOCAL)
        })
    }

    /// Host-visible bytes of the buffer (None for device-only memory).
    pub fn mapped(&self) -> Option<&[u8]> {
        self.allocation
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .map(|s| &s[..self.size as usize])
    }

    /// Host-visible bytes, mutable.
    pub fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        let size = self.size as usize;
        self.allocation
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .map(|s| &mut s[..size])
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // The owner waited for the GPU before dropping (all submits in
        // pointlens wait on a fence), so the buffer is not in use: the pool
        // may hand it out again, or destroy it.
        if let Some(allocation) = self.allocation.take() {
            let parts = Parts::Buffer {
                raw: self.raw,
                allocation,
            };
            self.ctx.recycle(&self.key, parts, self.complete);
        }
    }
}

/// The error of an allocation that failed: the resource, its size, and for
/// running out of memory, the flags that make a frame smaller.
fn allocation_error(what: &str, bytes: u64, e: &gpu_allocator::AllocationError) -> Error {
    let mib = bytes as f64 / f64::from(1 << 20);
    match e {
        gpu_allocator::AllocationError::OutOfMemory => Error::Allocation(format!(
            "out of device memory for {what}, {mib:.1} MiB; a smaller frame needs less: \
             --width/--height, --rdb-memory-mb (the RDB in tiles), --rdb-bins, --layers, \
             or --lod-px above 0"
        )),
        e => Error::Allocation(format!("{what}, {mib:.1} MiB: {e}")),
    }
}

/// Allocates memory; when the allocator refuses, frees the pool (what
/// earlier frames left for later ones) and tries once more.
fn allocate(ctx: &Context, desc: &AllocationCreateDesc<'_>) -> gpu_allocator::Result<Allocation> {
    let injected = super::context::injected_fault("vkAllocateMemory")
        .or_else(|| super::context::injected_fault(&format!("vkAllocateMemory@{}", desc.name)));
    if injected.is_some() {
        return Err(gpu_allocator::AllocationError::OutOfMemory);
    }
    let first = ctx.allocator().allocate(desc);
    match first {
        Ok(a) => Ok(a),
        Err(_) if ctx.pool_counts().2 > 0 => {
            ctx.release_pool();
            ctx.allocator().allocate(desc)
        }
        Err(e) => Err(e),
    }
}

/// A 2D image (optionally an array) with one view over all its layers.
pub struct Image {
    ctx: Arc<Context>,
    pub(super) raw: vk::Image,
    pub(super) view: vk::ImageView,
    format: vk::Format,
    width: u32,
    height: u32,
    layers: u32,
    /// Samples per pixel (1 unless made by [`Image::new_multisampled`]).
    samples: u32,
    allocation: Option<Allocation>,
    /// What it was made with: where it goes back to the pool.
    key: Key,
    /// Made completely (bound, viewed): may go back to the pool.
    complete: bool,
}

impl Image {
    /// Creates a device-local multisampled 2D image with `samples` samples
    /// per pixel (a count the device supports for the format and usage).
    pub fn new_multisampled(
        ctx: &Arc<Context>,
        name: &str,
        format: vk::Format,
        width: u32,
        height: u32,
        samples: u32,
        usage: vk::ImageUsageFlags,
    ) -> Result<Image> {
        Image::create(ctx, name, format, [width, height, 1], samples, usage)
    }

    /// Creates a device-local 2D image (`layers > 1` for an array image) and
    /// a view of it (`TYPE_2D_ARRAY` when layered).
    pub fn new_2d(
        ctx: &Arc<Context>,
        name: &str,
        format: vk::Format,
        width: u32,
        height: u32,
        layers: u32,
        usage: vk::ImageUsageFlags,
    ) -> Result<Image> {
        Image::create(ctx, name, format, [width, height, layers], 1, usage)
    }

    fn create(
        ctx: &Arc<Context>,
        name: &str,
        format: vk::Format,
        [width, height, layers]: [u32; 3],
        samples: u32,
        usage: vk::ImageUsageFlags,
    ) -> Result<Image> {
        let sample_flags = vk::SampleCountFlags::from_raw(samples);
        assert!(
            samples.is_power_of_two() && samples <= 64,
            "{samples} samples per pixel"
        );
        let key = Key::Image {
            name: name.to_owned(),
            format,
            extent: [width, height, layers],
            samples,
            usage,
        };
        let pooled = ctx.pool().take(&key);
        if let Some(Parts::Image {
            raw,
            view,
            allocation,
        }) = pooled
        {
            return Ok(Image {
                ctx: ctx.clone(),
                raw,
                view,
                format,
                width,
                height,
                layers,
                samples,
                allocation: Some(allocation),
                key,
                complete: true,
            });
        }
        ctx.pool().created += 1;
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width,
                height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(layers)
            .samples(sample_flags)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid device and create info.
        let raw = unsafe { ctx.device.create_image(&info, None) }.vk("vkCreateImage")?;
        // SAFETY: `raw` was just created on this device.
        let requirements = unsafe { ctx.device.get_image_memory_requirements(raw) };
        let allocation = allocate(
            ctx,
            &AllocationCreateDesc {
                name,
                requirements,
                location: MemoryLocation::GpuOnly,
                linear: false,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            },
        );
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: the image is unused and unbound.
                unsafe { ctx.device.destroy_image(raw, None) };
                return Err(allocation_error(
                    &format!("{name} ({width}x{height}x{layers})"),
                    requirements.size,
                    &e,
                ));
            }
        };
        let mut image = Image {
            ctx: ctx.clone(),
            raw,
            view: vk::ImageView::null(),
            format,
            width,
            height,
            layers,
            samples,
            allocation: Some(allocation),
            key,
            complete: false,
        };
        let a = image.allocation.as_ref().expect("just set");
        // SAFETY: the allocation satisfies the image's requirements; bound once.
        unsafe {
            ctx.device
                .bind_image_memory(raw, a.memory(), a.offset())
                .vk("vkBindImageMemory")?
        };
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw)
            .view_type(if layers > 1 {
                vk::ImageViewType::TYPE_2D_ARRAY
            } else {
                vk::ImageViewType::TYPE_2D
            })
            .format(format)
            .subresource_range(image.full_range());
        // SAFETY: the image is bound to memory and the view covers its range.
        image.view =
            unsafe { ctx.device.create_image_view(&view_info, None) }.vk("vkCreateImageView")?;
        ctx.set_name(raw, name);
        ctx.set_name(image.view, name);
        image.complete = true;
        Ok(image)
    }

    pub fn format(&self) -> vk::Format {
        self.format
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Array layers (1 for a plain 2D image).
    pub fn layers(&self) -> u32 {
        self.layers
    }

    /// Samples per pixel.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Whether the image was made on `ctx`.
    pub fn made_on(&self, ctx: &Context) -> bool {
        std::ptr::eq(&*self.ctx, ctx)
    }

    /// The aspect of this image's format.
    pub(super) fn aspect(&self) -> vk::ImageAspectFlags {
        match self.format {
            vk::Format::D32_SFLOAT | vk::Format::D16_UNORM | vk::Format::X8_D24_UNORM_PACK32 => {
                vk::ImageAspectFlags::DEPTH
            }
            _ => vk::ImageAspectFlags::COLOR,
        }
    }

    /// The subresource range covering every layer.
    pub(super) fn full_range(&self) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: self.aspect(),
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: self.layers,
        }
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        // Not in use (see Buffer::drop): to the pool.
        if let Some(allocation) = self.allocation.take() {
            let parts = Parts::Image {
                raw: self.raw,
                view: self.view,
                allocation,
            };
            self.ctx.recycle(&self.key, parts, self.complete);
        }
    }
}
