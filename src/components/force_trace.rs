//! The force trace of the loaded cine: Fx, Fy, Fz and |F| over its frames (newtons, the twin's
//! world frame) as the verdict reads them (combined where the rod was fitted, else H-Net's force
//! head), the range of |F| within each frame's 90 % intervals, the ablation band (0.1-0.3 N)
//! behind |F|, and the frame on screen as a cursor; a click moves the cine to that frame.

use leptos::prelude::*;
use wasm_bindgen::JsCast;

use crate::cine::CinePlayer;
use crate::force_reading::ABLATION_BAND_N;
use crate::studio::{CineStore, Studio};
use hnet_twin::reconstruction::physics_force::{EstimateKind, TipForceEstimate};
use hnet_units::TipForce;

/// The plot's size in SVG units, and its margins (left, right, top, bottom).
const WIDTH: f64 = 420.0;
const HEIGHT: f64 = 170.0;
const MARGIN: [f64; 4] = [40.0, 8.0, 8.0, 20.0];

/// One plotted quantity of a force (newtons).
type Component = fn(TipForce) -> f32;

/// The series: name, colour, and the value of a force.
const SERIES: [(&str, &str, Component); 4] = [
    ("Fx", "#d0453a", |f| f[0]),
    ("Fy", "#2f9e44", |f| f[1]),
    ("Fz", "#3867d6", |f| f[2]),
    ("|F|", "#222222", TipForce::magnitude),
];

/// What the plot draws, computed once per change of the trace or the frame.
#[derive(Clone, PartialEq)]
struct Plot {
    /// The SVG path of each series.
    paths: [String; 4],
    /// The range of |F| within each frame's 90 % intervals, as closed SVG shapes (one per run of
    /// frames that have it).
    range_path: String,
    /// Frames whose estimate is the combined one.
    combined: usize,
    /// The top of the force axis, newtons (the axis runs from minus this to this).
    top_n: f64,
    /// Frames in the cine.
    frames: usize,
    /// The frame on screen.
    frame: usize,
    /// Frames traced, with a force or without one.
    traced: usize,
    /// Traced frames without a force (the force head alone withheld on frames unlike those it
    /// was trained on).
    without: usize,
    /// The last frame's time, seconds, when known.
    end_s: Option<f64>,
}

fn x_of(frame: usize, frames: usize) -> f64 {
    let span = WIDTH - MARGIN[0] - MARGIN[1];
    MARGIN[0] + span * frame as f64 / frames.saturating_sub(1).max(1) as f64
}

fn y_of(force_n: f64, top_n: f64) -> f64 {
    let span = HEIGHT - MARGIN[2] - MARGIN[3];
    MARGIN[2] + span * (top_n - force_n) / (2.0 * top_n)
}

impl Plot {
    fn of(cine: &CinePlayer) -> Self {
        let frames = cine.frame_count();
        let forces: Vec<Option<TipForce>> = cine
            .estimates
            .iter()
            .map(|e| e.as_ref().and_then(|e| e.as_ref().ok()).map(|e| e.force_n))
            .collect();
        let ranges: Vec<Option<(f32, f32)>> = cine
            .estimates
            .iter()
            .map(|e| {
                e.as_ref()
                    .and_then(|e| e.as_ref().ok())
                    .and_then(TipForceEstimate::magnitude_range_n)
            })
            .collect();
        let largest = forces
            .iter()
            .flatten()
            .flat_map(|f| SERIES.map(|s| f64::from(s.2(*f)).abs()))
            .chain(ranges.iter().flatten().map(|r| f64::from(r.1)))
            .fold(0.0, f64::max);
        // Whole tenths of a newton, at least the ablation band's top and a margin.
        let top_n = ((largest.max(0.35) * 10.0).ceil() + 0.5).round() / 10.0;
        let paths = SERIES.map(|(_, _, value)| {
            let mut path = String::new();
            let mut pen_down = false;
            for (frame, force) in forces.iter().enumerate() {
                match force {
                    Some(f) => {
                        let (x, y) = (x_of(frame, frames), y_of(f64::from(value(*f)), top_n));
                        path.push_str(&format!(
                            "{}{x:.1},{y:.1} ",
                            if pen_down { "L" } else { "M" }
                        ));
                        pen_down = true;
                    }
                    None => pen_down = false,
                }
            }
            path
        });
        // Each run of frames with a range: along its top edge, back along its bottom edge.
        let mut range_path = String::new();
        let mut run: Vec<(usize, (f32, f32))> = Vec::new();
        let mut close = |run: &mut Vec<(usize, (f32, f32))>| {
            let point = |frame: usize, f: f32| {
                format!(
                    "{:.1},{:.1}",
                    x_of(frame, frames),
                    y_of(f64::from(f), top_n)
                )
            };
            let top = run.iter().map(|&(frame, r)| point(frame, r.1));
            let bottom = run.iter().rev().map(|&(frame, r)| point(frame, r.0));
            let points: Vec<String> = top.chain(bottom).collect();
            if !points.is_empty() {
                range_path.push_str(&format!("M{}Z ", points.join(" L")));
            }
            run.clear();
        };
        for (frame, range) in ranges.iter().enumerate() {
            match range {
                Some(r) => run.push((frame, *r)),
                None => close(&mut run),
            }
        }
        close(&mut run);
        let combined = cine
            .estimates
            .iter()
            .flatten()
            .filter(|e| e.as_ref().is_ok_and(|e| e.kind == EstimateKind::Combined))
            .count();
        Self {
            paths,
            range_path,
            combined,
            top_n,
            frames,
            frame: cine.frame,
            traced: cine.estimates.iter().flatten().count(),
            without: cine.frames_without_force(),
            end_s: cine.time_s(frames.saturating_sub(1)),
        }
    }
}

/// The trace plot.
#[component]
pub fn ForceTracePlot(cine: CineStore, studio: Studio) -> impl IntoView {
    let plot = Memo::new(move |_| cine.player.with(|c| c.as_ref().map(Plot::of)));
    let svg = NodeRef::<leptos::svg::Svg>::new();
    let on_click = move |ev: web_sys::MouseEvent| {
        let (Some(svg), Some(p)) = (svg.get_untracked(), plot.get_untracked()) else {
            return;
        };
        let Ok(element) = svg.dyn_into::<web_sys::Element>() else {
            return;
        };
        let rect = element.get_bounding_client_rect();
        let x = (f64::from(ev.client_x()) - rect.left()) * WIDTH / rect.width().max(1.0);
        let span = WIDTH - MARGIN[0] - MARGIN[1];
        let fraction = ((x - MARGIN[0]) / span).clamp(0.0, 1.0);
        let frame = (fraction * p.frames.saturating_sub(1) as f64).round() as usize;
        studio.seek_cine(frame);
    };
    move || {
        plot.get().map(|p| {
            let band = [ABLATION_BAND_N[1], ABLATION_BAND_N[0]].map(|f| y_of(f64::from(f), p.top_n));
            let cursor = x_of(p.frame, p.frames);
            let axis_end = match p.end_s {
                Some(t) => format!("{t:.2} s"),
                None => format!("frame {}", p.frames),
            };
            let plot_bottom = HEIGHT - MARGIN[3];
            view! {
                <figure class="force-trace">
                    <svg id="force-trace" node_ref=svg viewBox=format!("0 0 {WIDTH} {HEIGHT}")
                        role="img" data-traced=p.traced data-frame=p.frame data-combined=p.combined
                        aria-label=format!(
                            "Force trace: Fx, Fy, Fz and |F| in newtons over {} frames, {} traced \
                             ({} combined with the physics estimate, {} without a force, the rest \
                             H-Net's force head); the range of |F| within the 90 % intervals and \
                             the ablation band 0.1-0.3 N shaded; frame {} marked",
                            p.frames, p.traced, p.combined, p.without, p.frame + 1)
                        on:click=on_click>
                        <rect class="band" x=MARGIN[0] width=WIDTH - MARGIN[0] - MARGIN[1]
                            y=band[0] height=band[1] - band[0]></rect>
                        <line class="zero" x1=MARGIN[0] x2=WIDTH - MARGIN[1]
                            y1=y_of(0.0, p.top_n) y2=y_of(0.0, p.top_n)></line>
                        <line class="frame-axis" x1=MARGIN[0] x2=WIDTH - MARGIN[1]
                            y1=plot_bottom y2=plot_bottom></line>
                        {[p.top_n, 0.0, -p.top_n].map(|f| view! {
                            <text class="tick" x=MARGIN[0] - 4.0 y=y_of(f, p.top_n) + 3.0
                                text-anchor="end">{format!("{f:.1} N")}</text>
                        }).collect_view()}
                        <text class="tick" x=MARGIN[0] y=HEIGHT - 6.0>"0"</text>
                        <text class="tick" x=WIDTH - MARGIN[1] y=HEIGHT - 6.0 text-anchor="end">{axis_end}</text>
                        <path class="range" id="trace-range" d=p.range_path.clone()></path>
                        {SERIES.iter().zip(p.paths.clone()).map(|((name, colour, _), d)| view! {
                            <path class="series" data-series=*name d=d stroke=*colour
                                stroke-width=if *name == "|F|" { "2" } else { "1.3" }></path>
                        }).collect_view()}
                        <line id="trace-cursor" class="cursor" x1=cursor x2=cursor
                            y1=MARGIN[2] y2=plot_bottom></line>
                    </svg>
                    <figcaption>
                        {SERIES.iter().map(|(name, colour, _)| view! {
                            <span class="key"><span class="swatch" style:background=*colour></span>{*name}</span>
                        }).collect_view()}
                        <span class="key"><span class="swatch band"></span>"ablation band 0.1-0.3 N"</span>
                        <span class="key"><span class="swatch range"></span>"|F| within the 90 % intervals"</span>
                        {(p.traced > 0).then(|| format!(
                            " · {} of {} frames combined with the physics estimate, the rest H-Net's force head",
                            p.combined, p.traced))}
                        {(p.traced == 0).then_some(" · no force traced yet")}
                    </figcaption>
                </figure>
            }
        })
    }
}
