//! Where the CLI computes: Burn's flex CPU backend by default; ndarray, wgpu and CUDA when the
//! binary was built with the matching cargo feature.

use anyhow::bail;
use burn::tensor::Device;

/// A backend named on the command line (`--backend`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendChoice {
    /// Burn's flex: pure Rust, multi-threaded, SIMD (the default).
    Flex,
    /// Burn's ndarray backend (feature `ndarray`), for comparison.
    Ndarray,
    /// wgpu: Vulkan, Metal or DX12 GPUs, or a software adapter (feature `wgpu`).
    Wgpu,
    /// NVIDIA GPUs through CUDA (feature `cuda`).
    Cuda,
}

impl BackendChoice {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            BackendChoice::Flex => "flex",
            BackendChoice::Ndarray => "ndarray",
            BackendChoice::Wgpu => "wgpu",
            BackendChoice::Cuda => "cuda",
        }
    }

    /// The device, or an error saying how to build a binary that has it.
    pub fn device(self) -> anyhow::Result<Device> {
        let missing = |feature: &str| -> anyhow::Result<Device> {
            bail!(
                "this hnet was built without the `{feature}` backend: \
                 cargo build -p hnet-cli --features {feature}"
            )
        };
        match self {
            BackendChoice::Flex => Ok(Device::flex()),
            // Deprecated upstream in favour of flex; kept only to measure the two side by side.
            #[cfg(feature = "ndarray")]
            #[allow(deprecated)]
            BackendChoice::Ndarray => Ok(Device::ndarray()),
            #[cfg(not(feature = "ndarray"))]
            BackendChoice::Ndarray => missing("ndarray"),
            #[cfg(feature = "wgpu")]
            BackendChoice::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "wgpu"))]
            BackendChoice::Wgpu => missing("wgpu"),
            #[cfg(feature = "cuda")]
            BackendChoice::Cuda => Ok(Device::cuda(0usize)),
            #[cfg(not(feature = "cuda"))]
            BackendChoice::Cuda => missing("cuda"),
        }
    }
}
