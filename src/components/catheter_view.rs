//! The catheter in 3D: the reconstructed centreline, the rod fitted to it, both C-arms' X-ray
//! sources and detectors, and the tip force as 3D arrows (H-Net's, the physics estimate and, for
//! twin pairs, the truth). Drag or the arrow keys rotate it, the wheel or + and − zoom it.
//!
//! **Drawing approach: Canvas 2D of projected 3D lines.** The scene is a few hundred line
//! segments and points; [`crate::orbit_camera`] projects them (orthographic or perspective) and
//! the canvas' 2D context strokes them. This adds no dependency and a few kilobytes of wasm
//! (WebGL2 through web-sys would add shaders, buffers and a second rendering path for the same
//! lines), every piece of geometry is plain Rust tested natively (`cargo test`), and it draws
//! identically in headless Chromium without a GPU, where the end-to-end test reads its pixels.
//! Lines need no depth buffer: they are drawn back to front by kind (C-arms, rod, catheter,
//! arrows).

use leptos::prelude::*;

use crate::catheter_3d::{
    ARROW_MM_PER_NEWTON, CARM_SKETCH_SCALE, CArmSketch, Catheter3d, FitMasks, arrow_within,
    force_arrow_mm, scene_points,
};
use crate::components::stereo_view::{ESTIMATE_ARROW, TRUE_ARROW, context_2d, draw_arrow};
use crate::components::upload_geometry::UploadGeometry;
use crate::engine::Prediction;
use crate::keymap::{self, Command, Scope, scope_help};
use crate::orbit_camera::{OrbitCamera, Projection};
use crate::studio::{CatheterReading, Notices, PairStore, Studio, TwinStore};
use crate::workspace::{LabeledPair, PairSource};
use hnet_twin::simulator::carm::Biplane;
use hnet_units::TipForce;

/// Side of the 3D canvas, canvas pixels.
const SIDE: f64 = 400.0;
/// Colour of the reconstructed catheter.
const CATHETER: &str = "#f2f2f2";
/// Colour of the fitted rod.
const ROD: &str = "#8fa3b8";
/// Colour of the physics estimate's arrow.
pub(crate) const PHYSICS_ARROW: &str = "#ff6bd6";
/// Colours of view A's and view B's C-arm.
const CARM: [&str; 2] = ["#5fb3ff", "#ffa94d"];
/// Degrees per arrow key press (five times with Shift) and per dragged canvas pixel.
const KEY_STEP_DEG: f64 = 5.0;
const DRAG_DEG_PER_PX: f64 = 0.5;

/// Strokes a polyline of world points.
fn polyline(
    ctx: &web_sys::CanvasRenderingContext2d,
    camera: &OrbitCamera,
    points: &[[f64; 3]],
    colour: &str,
    width: f64,
) {
    ctx.set_stroke_style_str(colour);
    ctx.set_line_width(width);
    ctx.begin_path();
    let mut pen_down = false;
    for p in points {
        match camera.project(*p, SIDE) {
            Some(q) if pen_down => ctx.line_to(q[0], q[1]),
            Some(q) => {
                ctx.move_to(q[0], q[1]);
                pen_down = true;
            }
            None => pen_down = false,
        }
    }
    ctx.stroke();
}

/// Draws the scene of `catheter`.
fn draw(
    ctx: &web_sys::CanvasRenderingContext2d,
    reading: &CatheterReading,
    catheter: &Catheter3d,
    orbit: OrbitCamera,
    arrows: &[([f64; 3], TipForce, &str, bool)],
) {
    let camera = orbit.framing(
        &catheter.centreline_mm,
        &scene_points(catheter, &reading.views),
    );
    // The world's axes at the isocentre: patient left, anterior, head (20 mm).
    for (axis, name) in [
        ([20.0, 0.0, 0.0], "L"),
        ([0.0, 20.0, 0.0], "A"),
        ([0.0, 0.0, 20.0], "H"),
    ] {
        polyline(ctx, &camera, &[[0.0; 3], axis], "#4a5562", 1.0);
        if let Some(q) = camera.project(axis, SIDE) {
            ctx.set_fill_style_str("#7d8997");
            let _ = ctx.fill_text(name, q[0] + 3.0, q[1] - 3.0);
        }
    }
    for (index, carm) in reading.views.views().into_iter().enumerate() {
        let sketch = CArmSketch::of(carm);
        let colour = CARM[index];
        ctx.set_global_alpha(0.35);
        for corner in sketch.detector_mm {
            polyline(ctx, &camera, &[sketch.source_mm, corner], colour, 1.0);
        }
        ctx.set_global_alpha(1.0);
        let d = sketch.detector_mm;
        polyline(ctx, &camera, &[d[0], d[1], d[2], d[3], d[0]], colour, 2.0);
        if let Some(q) = camera.project(sketch.source_mm, SIDE) {
            ctx.set_fill_style_str(colour);
            ctx.begin_path();
            let _ = ctx.arc(q[0], q[1], 5.0, 0.0, std::f64::consts::TAU);
            ctx.fill();
            let _ = ctx.fill_text(
                &format!("source {}", ["A", "B"][index]),
                q[0] + 7.0,
                q[1] + 4.0,
            );
        }
    }
    let dash = js_sys::Array::new();
    dash.push(&4.0.into());
    dash.push(&3.0.into());
    let _ = ctx.set_line_dash(&dash);
    polyline(ctx, &camera, &catheter.rod_mm, ROD, 1.5);
    let _ = ctx.set_line_dash(&js_sys::Array::new());
    polyline(ctx, &camera, &catheter.centreline_mm, CATHETER, 3.0);
    for &(tip, force, colour, dashed) in arrows {
        let [from, to] = force_arrow_mm(tip, force);
        if let (Some(a), Some(b)) = (camera.project(from, SIDE), camera.project(to, SIDE))
            && let Some(b) = arrow_within(a, b, SIDE, 8.0)
        {
            draw_arrow(ctx, a, b, colour, dashed);
        }
    }
}

/// `text` with its first letter in upper case.
fn capitalised(text: &str) -> String {
    let mut chars = text.chars();
    chars
        .next()
        .map(|c| c.to_uppercase().chain(chars).collect())
        .unwrap_or_default()
}

/// The 3D view with its legend and summary.
#[component]
pub fn CatheterView(
    pairs: PairStore,
    twin: TwinStore,
    notices: Notices,
    /// H-Net's prediction of the pair on screen.
    prediction: Memo<Option<Prediction>>,
    studio: Studio,
) -> impl IntoView {
    let canvas = NodeRef::<leptos::html::Canvas>::new();
    let drag = StoredValue::new(None::<[f64; 2]>);
    // The reading of the pair on screen (an older pair's is not shown).
    let reading = Memo::new(move |_| {
        let id = pairs.shown_id()?;
        twin.catheter
            .with(|c| c.as_ref().filter(|c| c.id == id).cloned())
    });
    let estimate = move || prediction.with(|p| p.as_ref().and_then(|p| p.force_n));
    let truth = move || {
        pairs.with_shown(|p| match &p?.source {
            PairSource::Twin {
                true_force_n,
                tip_mm,
                ..
            } => Some((*tip_mm, *true_force_n)),
            PairSource::Upload { .. } | PairSource::Dicom { .. } => None,
        })
    };

    Effect::new(move |_| {
        let Some(canvas) = canvas.get() else { return };
        let Some(ctx) = context_2d(&canvas) else {
            return;
        };
        ctx.set_fill_style_str("#15181c");
        ctx.fill_rect(0.0, 0.0, SIDE, SIDE);
        ctx.set_font("12px sans-serif");
        let orbit = twin.orbit.get();
        let (estimate, truth) = (estimate(), truth());
        reading.with(|reading| {
            let Some(reading) = reading else { return };
            let Ok(catheter) = &reading.result else {
                return;
            };
            let tip = catheter.tip_mm();
            let mut arrows = Vec::new();
            if let Some(f) = estimate {
                arrows.push((tip, f, ESTIMATE_ARROW, false));
            }
            arrows.push((tip, catheter.force_n, PHYSICS_ARROW, false));
            if let Some((true_tip, f)) = truth {
                arrows.push((true_tip, f, TRUE_ARROW, true));
            }
            draw(&ctx, reading, catheter, orbit, &arrows);
        });
    });

    let rotate = move |yaw: f64, pitch: f64| twin.orbit.update(|o| *o = o.rotated(yaw, pitch));
    let on_down = move |ev: web_sys::PointerEvent| {
        if ev.button() != 0 {
            return;
        }
        if let Some(c) = canvas.get_untracked() {
            let _ = c.set_pointer_capture(ev.pointer_id());
        }
        drag.set_value(Some([f64::from(ev.client_x()), f64::from(ev.client_y())]));
    };
    let on_move = move |ev: web_sys::PointerEvent| {
        let Some(last) = drag.get_value() else { return };
        let now = [f64::from(ev.client_x()), f64::from(ev.client_y())];
        rotate(
            (now[0] - last[0]) * DRAG_DEG_PER_PX,
            (now[1] - last[1]) * DRAG_DEG_PER_PX,
        );
        drag.set_value(Some(now));
    };
    let on_up = move |_: web_sys::PointerEvent| drag.set_value(None);
    let on_wheel = move |ev: web_sys::WheelEvent| {
        ev.prevent_default();
        let factor = (-ev.delta_y() * 0.002).exp();
        twin.orbit.update(|o| *o = o.zoomed(factor));
    };
    let on_key = move |ev: web_sys::KeyboardEvent| {
        let control = ev.ctrl_key() || ev.meta_key();
        let Some(command) = keymap::command(Scope::Scene, &ev.key(), control, ev.shift_key())
        else {
            return;
        };
        let step = if ev.shift_key() {
            5.0 * KEY_STEP_DEG
        } else {
            KEY_STEP_DEG
        };
        match command {
            Command::Left => rotate(-step, 0.0),
            Command::Right => rotate(step, 0.0),
            Command::Up => rotate(0.0, -step),
            Command::Down => rotate(0.0, step),
            Command::Grow => twin.orbit.update(|o| *o = o.zoomed(1.25)),
            Command::Shrink => twin.orbit.update(|o| *o = o.zoomed(0.8)),
            Command::ResetView => twin.orbit.update(|o| {
                *o = OrbitCamera {
                    projection: o.projection,
                    ..OrbitCamera::default()
                }
            }),
            Command::ToggleProjection => twin.orbit.update(|o| *o = o.toggled_projection()),
            _ => return,
        }
        ev.prevent_default();
    };

    let summary = move || {
        reading.with(|r| match r {
            Some(CatheterReading {
                result: Ok(c),
                millis,
                ..
            }) => format!(
                "{}; reconstructed and fitted in {millis:.0} ms.",
                capitalised(&c.summary())
            ),
            Some(CatheterReading { result: Err(_), .. }) => {
                "No catheter in 3D for this pair.".into()
            }
            None => "No pair, or not reconstructed yet.".into(),
        })
    };
    let error = move || reading.with(|r| r.as_ref().and_then(|r| r.result.clone().err()));
    let state = move || {
        reading.with(|r| match r {
            Some(CatheterReading { result: Ok(_), .. }) => "ready",
            Some(_) => "failed",
            None => "none",
        })
    };
    let orbit_text = move || {
        let o = twin.orbit.get();
        format!(
            "{:+.0}° / {:+.0}° · {:.1}× · {}",
            o.yaw_deg,
            o.pitch_deg,
            o.zoom,
            match o.projection {
                Projection::Perspective => "perspective",
                Projection::Orthographic => "orthographic",
            }
        )
    };
    let keys = scope_help(Scope::Scene);
    let title = keys.clone();

    // The uploaded pair on screen and the C-arms stated for it.
    // A memo: the form resets only when another upload is shown or its geometry changes, not on
    // every workspace update (a stroke, a label).
    let upload = Memo::new(move |_| {
        pairs.with_shown(|p| match p {
            Some(LabeledPair {
                id,
                source: PairSource::Upload { views, .. },
                ..
            }) => Some((id.clone(), *views)),
            _ => None,
        })
    });
    let on_state = Callback::new(move |(id, views): (String, Option<Biplane>)| {
        // Stating an upload's C-arms labels it: a draft upload is kept first.
        let Some(id) = (if pairs.showing_draft() {
            studio.labeled_pair_id()
        } else {
            Some(id)
        }) else {
            return;
        };
        let stated = views.is_some();
        pairs.edit(|ws| ws.set_upload_views(&id, views).then_some(id.clone()));
        notices.info(if stated {
            format!("{id}: C-arm geometry stated; the catheter is reconstructed with it")
        } else {
            format!("{id}: back to the default C-arms (assumed)")
        });
    });
    let on_error = Callback::new(move |text: String| notices.error(text));

    view! {
        <section class="catheter-3d" aria-labelledby="catheter-3d-title">
            <h2 id="catheter-3d-title">"The catheter in 3D"</h2>
            <figure class="scene">
                <canvas id="catheter-3d" width=SIDE height=SIDE node_ref=canvas tabindex="0"
                    role="img" title=title
                    aria-label=move || format!("3D view of the catheter. {} Keys: {keys}.", summary())
                    data-state=state
                    data-pair=move || reading.with(|r| r.as_ref().map(|r| r.id.clone()).unwrap_or_default())
                    data-millis=move || reading.with(|r| r.as_ref().map(|r| format!("{:.1}", r.millis)).unwrap_or_default())
                    on:pointerdown=on_down on:pointermove=on_move on:pointerup=on_up
                    on:pointercancel=on_up on:wheel=on_wheel on:keydown=on_key></canvas>
                <figcaption>
                    <span id="catheter-3d-orbit">{orbit_text}</span>
                    " · drag or ← → ↑ ↓ to rotate, wheel or + / − to zoom, Home resets, O switches the projection"
                </figcaption>
            </figure>
            <p class="legend">
                <span class="line catheter"></span>"reconstructed catheter "
                <span class="line rod"></span>"fitted rod "
                <span class="arrow estimate"></span>"H-Net's force "
                <span class="arrow physics"></span>"physics force "
                <span class="arrow truth"></span>"true force (twin) · "
                {format!("arrows {ARROW_MM_PER_NEWTON:.0} mm per N · ")}
                <span class="dot view-a"></span>"C-arm A "
                <span class="dot view-b"></span>"C-arm B (sources and detectors drawn at "
                {format!("{:.0} % of their size about the isocentre)", CARM_SKETCH_SCALE * 100.0)}
                " · axes (20 mm): L the patient's left, A anterior, H the head · an arrow longer than the view is cut at its edge"
            </p>
            <label class="fit-masks">
                "Fit the rod to "
                <select id="fit-masks" on:change=move |ev| {
                    if let Some(choice) = FitMasks::from_value(&event_target_value(&ev)) {
                        twin.fit_masks.set(choice);
                    }
                }>
                    {[
                        (FitMasks::LabelsFirst, "the label masks (H-Net's where there are none)"),
                        // On a twin pair: the physics estimate as a real pair would get it, and
                        // the Combined force row the bundled weights are calibrated for.
                        (FitMasks::Hnet, "H-Net's masks"),
                    ].into_iter().map(|(choice, text)| view! {
                        <option value=choice.value()
                            selected=move || twin.fit_masks.get() == choice>{text}</option>
                    }).collect_view()}
                </select>
            </label>
            <p id="catheter-summary" role="status">{summary}</p>
            {move || error().map(|e| view! { <p id="catheter-error" class="warning">{e}</p> })}
            <UploadGeometry upload=upload on_state=on_state on_error=on_error/>
        </section>
    }
}
