//! Errors of the GPU engine.

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (on Linux install a Vulkan driver, e.g. Debian's mesa-vulkan-drivers and libvulkan1 for the lavapipe software driver): {0}"
    )]
    NoAdapter(String),
    #[error("the GPU adapter '{adapter}' refused a device: {source}")]
    Device {
        adapter: String,
        source: wgpu::RequestDeviceError,
    },
    #[error("GPU buffer readback failed: {0}")]
    Map(String),
    #[error("GPU wait failed: {0}")]
    Poll(String),
    #[error("GPU validation error in {kernel}: {message}")]
    Validation {
        kernel: &'static str,
        message: String,
    },
}
