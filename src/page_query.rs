//! The switches a page address's query can set (`?a=1&webgpu-tolerance-scale=0`): diagnosis and
//! test hooks, each with its name, its reader and its default in one place. Read natively from
//! the query string, so that they are tested without a browser.

/// Scales both tolerances of the WebGPU check ([`crate::webgpu_check`]): `0` demands equal
/// results, a negative scale fails every check. Default 1.
pub const WEBGPU_TOLERANCE_SCALE: &str = "webgpu-tolerance-scale";

/// How long a CPU worker may take to read one view before it counts as stopped and is replaced,
/// seconds (a whole number, at least 1). Default [`CPU_VIEW_TIMEOUT_S`]; the browser tests
/// shorten it to see a silent worker replaced.
pub const CPU_VIEW_TIMEOUT: &str = "cpu-view-timeout-s";

/// A CPU worker's default time to read one view, seconds: a view at 224 px takes about a tenth of
/// a second (docs/benchmarks.md).
pub const CPU_VIEW_TIMEOUT_S: u32 = 60;

/// Views handed to one CPU worker at once (a whole number, at least 1): the one it reads and the
/// next, waiting in its message queue, so that it starts the next the moment it finishes one,
/// even while the page's thread is busy. Default [`CPU_VIEWS_PER_WORKER_DEFAULT`]; `1` hands a
/// worker its next view only once it has answered (the pool before 2026-12-07), for A/B timings.
pub const CPU_VIEWS_PER_WORKER: &str = "cpu-views-per-worker";

/// A CPU worker's default views in hand: with one, a worker that finished while the page's thread
/// fitted a traced frame's rod (30-40 ms) sat idle until the page handed it another view.
pub const CPU_VIEWS_PER_WORKER_DEFAULT: usize = 2;

/// `cpu-fused=0` keeps the CPU workers on the module without relaxed SIMD (crates/hnet-cpu) in
/// a browser that has it, so that both modules can be timed and tested in one browser. Any other
/// value, or none, lets the page choose ([`crate::cpu_pool::CpuModule::for_this_browser`]).
pub const CPU_FUSED: &str = "cpu-fused";

/// `winograd-tiles=2` keeps the CPU workers' convolutions on Winograd's F(2x2, 3x3) tiles
/// rather than F(4x4, 3x3) where those serve (`hnet_conv::use_large_winograd_tiles`), so that
/// both can be timed in one build. Any other value, or none, lets the kernels choose.
pub const WINOGRAD_TILES: &str = "winograd-tiles";

/// The fine-tune's patience, epochs (a whole number, at least 1): `tune-patience=100` runs
/// every epoch asked for even where the held-back loss stops improving early, so that a
/// benchmark times them all (end2end/bench-fine-tune.mjs). Default the page's
/// ([`hnet_model::fine_tune::FineTuneSettings::patience`]).
pub const TUNE_PATIENCE: &str = "tune-patience";

/// The value of parameter `key` in `query` (with or without its leading `?`), if given.
fn value<'a>(query: &'a str, key: &str) -> Option<&'a str> {
    query
        .trim_start_matches('?')
        .split('&')
        .filter_map(|pair| pair.split_once('='))
        .find(|(k, _)| *k == key)
        .map(|(_, value)| value)
}

/// The WebGPU check's tolerance scale `query` asks for; 1 when absent or unreadable.
pub fn webgpu_tolerance_scale(query: &str) -> f64 {
    value(query, WEBGPU_TOLERANCE_SCALE)
        .and_then(|value| value.parse::<f64>().ok())
        .filter(|scale| scale.is_finite())
        .unwrap_or(1.0)
}

/// The CPU workers' time to read one view `query` asks for, seconds;
/// [`CPU_VIEW_TIMEOUT_S`] when absent, zero or unreadable.
pub fn cpu_view_timeout_s(query: &str) -> u32 {
    value(query, CPU_VIEW_TIMEOUT)
        .and_then(|value| value.parse::<u32>().ok())
        .filter(|&seconds| seconds >= 1)
        .unwrap_or(CPU_VIEW_TIMEOUT_S)
}

/// The views a CPU worker holds at once that `query` asks for; [`CPU_VIEWS_PER_WORKER_DEFAULT`]
/// when absent, zero or unreadable.
pub fn cpu_views_per_worker(query: &str) -> usize {
    value(query, CPU_VIEWS_PER_WORKER)
        .and_then(|value| value.parse::<usize>().ok())
        .filter(|&views| views >= 1)
        .unwrap_or(CPU_VIEWS_PER_WORKER_DEFAULT)
}

/// The fine-tune's patience `query` asks for, if a whole number of at least 1 ([`TUNE_PATIENCE`]).
pub fn tune_patience(query: &str) -> Option<usize> {
    value(query, TUNE_PATIENCE)
        .and_then(|value| value.parse::<usize>().ok())
        .filter(|&epochs| epochs >= 1)
}

/// False when the query turns the fused CPU module off ([`CPU_FUSED`]`=0`).
pub fn cpu_fused_allowed(query: &str) -> bool {
    value(query, CPU_FUSED) != Some("0")
}

/// False when the query keeps the CPU workers on F(2x2, 3x3) tiles ([`WINOGRAD_TILES`]`=2`).
pub fn large_winograd_tiles_allowed(query: &str) -> bool {
    value(query, WINOGRAD_TILES) != Some("2")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn switches_come_from_the_query_or_take_their_default() {
        assert_eq!(webgpu_tolerance_scale(""), 1.0);
        assert_eq!(webgpu_tolerance_scale("?webgpu-tolerance-scale=-1"), -1.0);
        assert_eq!(webgpu_tolerance_scale("?a=b&webgpu-tolerance-scale=0"), 0.0);
        assert_eq!(webgpu_tolerance_scale("?webgpu-tolerance-scale=inf"), 1.0);
        assert_eq!(webgpu_tolerance_scale("?webgpu-tolerance-scale"), 1.0);
        assert!(cpu_fused_allowed("") && cpu_fused_allowed("?cpu-fused=1"));
        assert_eq!(tune_patience("?tune-patience=100"), Some(100));
        assert_eq!(tune_patience("?tune-patience=0"), None);
        assert_eq!(tune_patience(""), None);
        assert!(!cpu_fused_allowed("?a=b&cpu-fused=0"));
        assert!(
            large_winograd_tiles_allowed("") && large_winograd_tiles_allowed("?winograd-tiles=4")
        );
        assert!(!large_winograd_tiles_allowed(
            "?cpu-fused=0&winograd-tiles=2"
        ));
        assert_eq!(cpu_views_per_worker(""), CPU_VIEWS_PER_WORKER_DEFAULT);
        assert_eq!(
            cpu_views_per_worker("?cpu-views-per-worker=0"),
            CPU_VIEWS_PER_WORKER_DEFAULT
        );
        assert_eq!(cpu_views_per_worker("?cpu-views-per-worker=1"), 1);
        assert_eq!(cpu_view_timeout_s(""), CPU_VIEW_TIMEOUT_S);
        assert_eq!(cpu_view_timeout_s("?cpu-view-timeout-s=5"), 5);
        assert_eq!(
            cpu_view_timeout_s("webgpu-tolerance-scale=0&cpu-view-timeout-s=2"),
            2
        );
        for unreadable in [
            "?cpu-view-timeout-s=0",
            "?cpu-view-timeout-s=-3",
            "?cpu-view-timeout-s=1.5",
            "?cpu-view-timeout-s=",
        ] {
            assert_eq!(
                cpu_view_timeout_s(unreadable),
                CPU_VIEW_TIMEOUT_S,
                "{unreadable}"
            );
        }
    }
}
