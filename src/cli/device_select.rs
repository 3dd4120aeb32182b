//! Mesa's Vulkan device-selection layer kept out of the way.
//!
//! Mesa installs `VK_LAYER_MESA_device_select` as an implicit layer: every
//! Vulkan instance loads it, and it connects to the Wayland and X11 displays
//! to find the GPU that drives the screen. On a server or CI runner with no
//! display — where tirewear runs — Wayland's client library then prints
//! "error: XDG_RUNTIME_DIR is invalid or not set in the environment." twice
//! to stderr, through no logger, in the middle of a run that succeeds.
//! tirewear never draws to a screen and picks its adapter itself (wgpu's
//! high-performance preference, or `WGPU_ADAPTER_NAME`), so the layer has
//! nothing to choose: `NODEVICE_SELECT=1` (the layer's own switch) turns it
//! off. A user's own `NODEVICE_SELECT` or `MESA_VK_DEVICE_SELECT` (asking
//! the layer for a device) wins: with either set, nothing is changed.

/// Sets `NODEVICE_SELECT=1` unless the user chose; call once, before any
/// thread starts.
pub(crate) fn quiet() {
    let user_set = ["NODEVICE_SELECT", "MESA_VK_DEVICE_SELECT"]
        .iter()
        .any(|v| std::env::var_os(v).is_some());
    if !user_set {
        // SAFETY: called from `main` before any other thread exists, so
        // nothing reads the environment while it changes.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}
