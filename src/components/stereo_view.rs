//! The two views side by side: the images with H-Net's masks and the label masks overlaid, the
//! tip force as arrows, and the brush, eraser, zoom and pan that correct the labels.

use hnet_twin::simulator::carm::CArm;
use hnet_units::mask;
use leptos::prelude::*;
use wasm_bindgen::{Clamped, JsCast};

use crate::catheter_3d::{epipolar_line, pair_views};
use crate::components::on_slider;
use crate::engine::Prediction;
use crate::imaging::{WORK_SIZE, estimate_tip, force_arrow, overlay, project, rgba};
use crate::keymap::{self, Command, Scope, tooltip};
use crate::studio::{
    CANVAS_SIDE, DisplaySettings, Notices, PairStore, PointerTool, SourceTab, Studio, ViewTransform,
};
use crate::workspace::{PairSource, View};

/// Colour of H-Net's masks.
const PREDICTION_COLOUR: [u8; 3] = [0, 200, 255];
/// Colour of the label masks.
const LABEL_COLOUR: [u8; 3] = [255, 110, 0];
/// Colour of the estimated force arrow.
pub(crate) const ESTIMATE_ARROW: &str = "#ffd400";
/// Colour of the true force arrow (twin pairs).
pub(crate) const TRUE_ARROW: &str = "#3ddc84";
/// Colour of the pointer's epipolar line, drawn in the other view, and of its casing.
const EPIPOLAR_LINE: &str = "#e4d2ff";
const EPIPOLAR_CASING: &str = "rgba(20, 10, 40, 0.85)";

/// The toolbar and both views.
#[component]
pub fn StereoView(
    pairs: PairStore,
    display: DisplaySettings,
    notices: Notices,
    /// H-Net's prediction of the pair on screen.
    prediction: Memo<Option<Prediction>>,
    studio: Studio,
) -> impl IntoView {
    let tool_button = move |tool: PointerTool,
                            id: &'static str,
                            label: &'static str,
                            command: Command| {
        view! {
            <button id=id class="tool" aria-pressed=move || (display.tool.get() == tool).to_string()
                title=tooltip(label, command) on:click=move |_| display.tool.set(tool)>
                {label}
            </button>
        }
    };
    // A slider and a checkbox bound to a setting.
    let slider = |id: &'static str, [min, max, step]: [&'static str; 3], value: RwSignal<f64>| {
        view! {
            <input id=id type="range" min=min max=max step=step
                prop:value=move || value.get().to_string()
                on:input=on_slider(move |v| value.set(v))/>
        }
    };
    let checkbox = |id: &'static str, value: RwSignal<bool>| {
        view! {
            <input id=id type="checkbox" prop:checked=move || value.get()
                on:change=move |ev| value.set(event_target_checked(&ev))/>
        }
    };
    let can = move || pairs.workspace.with(|ws| ws.can_undo_redo());
    let has_prediction = move || prediction.with(Option::is_some);
    view! {
        <div class="toolbar" role="toolbar" aria-label="Labeling tools">
            <button id="run-model" class="primary" title=tooltip("Run H-Net", Command::RunModel)
                disabled=move || notices.busy.get().is_some() || pairs.shown_id().is_none()
                on:click=move |_| studio.run_model()>"Run H-Net"</button>
            <button id="accept-masks" title=tooltip("Use H-Net's masks as the labels", Command::AcceptMasks)
                disabled=move || !has_prediction()
                on:click=move |_| studio.accept_predicted_masks()>"Use H-Net masks as labels"</button>
            <span class="group">
                {tool_button(PointerTool::Brush, "tool-brush", "Brush", Command::Brush)}
                {tool_button(PointerTool::Eraser, "tool-eraser", "Eraser", Command::Eraser)}
                {tool_button(PointerTool::Pan, "tool-pan", "Pan", Command::Pan)}
                {move || pairs.showing_cine_frame().then(|| tool_button(
                    PointerTool::WindowLevel, "tool-window-level", "Window/level", Command::WindowLevel))}
            </span>
            <label class="slider compact">"Size"
                {slider("brush-size", ["1", "20", "0.5"], display.brush_radius)}
                <output>{move || format!("{:.1} px", display.brush_radius.get())}</output>
            </label>
            <span class="group">
                <button id="undo" title=tooltip("Undo", Command::Undo) disabled=move || !can().0
                    on:click=move |_| studio.undo_redo(false)>"Undo"</button>
                <button id="redo" title=tooltip("Redo", Command::Redo) disabled=move || !can().1
                    on:click=move |_| studio.undo_redo(true)>"Redo"</button>
            </span>
            <span class="group">
                <label>{checkbox("show-prediction", display.show_prediction)}
                    <span class="swatch prediction"></span>"H-Net masks"</label>
                <label>{checkbox("show-label", display.show_label)}
                    <span class="swatch label"></span>"Labels"</label>
            </span>
            <label class="slider compact">"Opacity"
                {slider("opacity", ["0", "1", "0.05"], display.opacity)}
            </label>
            <button id="reset-zoom" title=tooltip("Fit both views", Command::FitViews)
                on:click=move |_| display.fit_views()>"Fit"</button>
        </div>
        {move || pairs.showing_draft().then(|| view! {
            <p class="draft-note">
                {move || if pairs.showing_cine_frame() {
                    "DICOM cine frame (not kept yet). "
                } else if pairs.showing_upload_draft() {
                    "Your pair (not kept yet: it joins your pairs when you label it or keep it). "
                } else if display.tab.get() == SourceTab::Images {
                    "A sample pair from the digital twin, with H-Net's masks, force and 3D view: \
                     load your own pair above, or change this one in the Digital twin tab. "
                } else {
                    "Live twin pair (not kept yet). "
                }}
                <button id="keep-draft" class="primary" on:click=move |_| studio.keep_draft()>"Keep this pair"</button>
            </p>
        })}
        <div class="views">
            <ViewCanvas view=View::A pairs=pairs display=display notices=notices prediction=prediction studio=studio/>
            <ViewCanvas view=View::B pairs=pairs display=display notices=notices prediction=prediction studio=studio/>
        </div>
        <p class="legend" title="The force arrows are the tip force projected on each view">
            <span class="arrow estimate"></span>"H-Net's force "
            <span class="arrow truth"></span>"true force (twin) · "
            {crate::imaging::ARROW_PX_PER_NEWTON}" px per N · "
            <span class="arrow epipolar"></span>"epipolar line of the pointer"
        </p>
    }
}

pub(crate) fn context_2d(
    canvas: &web_sys::HtmlCanvasElement,
) -> Option<web_sys::CanvasRenderingContext2d> {
    canvas.get_context("2d").ok()??.dyn_into().ok()
}

/// Draws an arrow from `from` to `to` (canvas pixels).
pub(crate) fn draw_arrow(
    ctx: &web_sys::CanvasRenderingContext2d,
    from: [f64; 2],
    to: [f64; 2],
    colour: &str,
    dashed: bool,
) {
    let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
    let length = (dx * dx + dy * dy).sqrt();
    ctx.set_stroke_style_str(colour);
    ctx.set_fill_style_str(colour);
    ctx.set_line_width(3.0);
    let dash = js_sys::Array::new();
    if dashed {
        dash.push(&7.0.into());
        dash.push(&5.0.into());
    }
    let _ = ctx.set_line_dash(&dash);
    ctx.begin_path();
    ctx.arc(from[0], from[1], 3.5, 0.0, std::f64::consts::TAU)
        .ok();
    ctx.fill();
    if length < 2.0 {
        return;
    }
    ctx.begin_path();
    ctx.move_to(from[0], from[1]);
    ctx.line_to(to[0], to[1]);
    ctx.stroke();
    let _ = ctx.set_line_dash(&js_sys::Array::new());
    let (ux, uy) = (dx / length, dy / length);
    let head = 12.0f64.min(length * 0.5);
    ctx.begin_path();
    ctx.move_to(to[0], to[1]);
    ctx.line_to(
        to[0] - head * ux + head * 0.5 * uy,
        to[1] - head * uy - head * 0.5 * ux,
    );
    ctx.line_to(
        to[0] - head * ux - head * 0.5 * uy,
        to[1] - head * uy + head * 0.5 * ux,
    );
    ctx.close_path();
    ctx.fill();
}

/// What the pointer is doing on a view.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Gesture {
    /// Painting; the last image point.
    Stroke([f64; 2]),
    /// Panning; the last canvas point.
    Pan([f64; 2]),
    /// Changing the window/level of a DICOM frame; the last canvas point.
    Window([f64; 2]),
}

/// One view's canvas.
#[component]
fn ViewCanvas(
    view: View,
    pairs: PairStore,
    display: DisplaySettings,
    notices: Notices,
    /// H-Net's prediction of the pair on screen.
    prediction: Memo<Option<Prediction>>,
    studio: Studio,
) -> impl IntoView {
    let index = view.index();
    let transform = display.transforms[index];
    let canvas = NodeRef::<leptos::html::Canvas>::new();
    let pointer = RwSignal::new(None::<[f64; 2]>);
    let gesture = StoredValue::new(None::<Gesture>);
    // The composited image at its own size, drawn scaled onto the view.
    let offscreen = StoredValue::new_local(
        web_sys::window()
            .and_then(|w| w.document())
            .and_then(|d| d.create_element("canvas").ok())
            .and_then(|c| c.dyn_into::<web_sys::HtmlCanvasElement>().ok())
            .inspect(|c| {
                c.set_width(WORK_SIZE.width as u32);
                c.set_height(WORK_SIZE.height as u32);
            }),
    );

    // The epipolar line, in this view, of the pointer on the other view (image pixels).
    let epipolar = Memo::new(move |_| {
        let (other, at) = display.epipolar_pointer.get()?;
        if other == view {
            return None;
        }
        pairs.with_shown(|pair| epipolar_line(&pair_views(pair?), view, at))
    });

    Effect::new(move |_| {
        let Some(canvas) = canvas.get() else { return };
        let Some(ctx) = context_2d(&canvas) else {
            return;
        };
        let t = transform.get();
        ctx.set_fill_style_str("#15181c");
        ctx.fill_rect(0.0, 0.0, CANVAS_SIDE, CANVAS_SIDE);
        let (show_prediction, show_label) =
            (display.show_prediction.get(), display.show_label.get());
        let opacity = display.opacity.get() as f32;
        let arrows = pairs.with_shown(|pair| {
            let pair = pair?;
            let prediction = prediction.get();
            let mut rgb = pair.image(view).to_vec();
            let predicted_mask = prediction.as_ref().map(|p| match view {
                View::A => &p.mask_a,
                View::B => &p.mask_b,
            });
            if show_prediction && let Some(mask) = predicted_mask {
                rgb = overlay(&rgb, mask.iter().copied(), PREDICTION_COLOUR, opacity);
            }
            if show_label && pair.masks_labeled {
                let label = pair.mask(view).iter().map(|&m| f32::from(m) / 255.0);
                rgb = overlay(&rgb, label, LABEL_COLOUR, opacity);
            }
            let offscreen = offscreen.get_value()?;
            let image = web_sys::ImageData::new_with_u8_clamped_array_and_sh(
                Clamped(&rgba(&rgb)),
                WORK_SIZE.width as u32,
                WORK_SIZE.height as u32,
            )
            .ok()?;
            context_2d(&offscreen)?
                .put_image_data(&image, 0.0, 0.0)
                .ok()?;
            ctx.set_image_smoothing_enabled(false);
            let _ = ctx.draw_image_with_html_canvas_element_and_dw_and_dh(
                &offscreen,
                t.offset[0],
                t.offset[1],
                WORK_SIZE.width as f64 * t.scale,
                WORK_SIZE.height as f64 * t.scale,
            );
            // Where the tip is and how the view sees the world: exact for twin pairs; for
            // uploads and DICOM frames, the tip found in the masks and the pair's geometry (the
            // default biplane's, or the DICOM headers').
            let (tip, carm): (Option<[f64; 2]>, CArm) = match &pair.source {
                PairSource::Twin { tip_mm, views, .. } => {
                    let carm = if view == View::A { views.a } else { views.b };
                    (Some(project(&carm, *tip_mm)), carm)
                }
                PairSource::Upload { .. } | PairSource::Dicom { .. } => {
                    let default = pair_views(pair);
                    let carm = if view == View::A {
                        default.a
                    } else {
                        default.b
                    };
                    let tip = if pair.masks_labeled {
                        estimate_tip(pair.mask(view), WORK_SIZE, mask::LABEL_THRESHOLD)
                    } else {
                        predicted_mask
                            .and_then(|m| estimate_tip(m, WORK_SIZE, mask::MASK_THRESHOLD))
                    };
                    (tip, carm)
                }
            };
            let tip = tip?;
            Some([
                prediction
                    .and_then(|p| p.force_n)
                    .map(|f| force_arrow(&carm, tip, f)),
                pair.true_force().map(|f| force_arrow(&carm, tip, f)),
            ])
        });
        for (arrow, colour, dashed) in arrows
            .into_iter()
            .flatten()
            .zip([(ESTIMATE_ARROW, false), (TRUE_ARROW, true)])
            .filter_map(|(a, (c, d))| a.map(|a| (a, c, d)))
        {
            draw_arrow(
                &ctx,
                t.to_canvas(arrow[0]),
                t.to_canvas(arrow[1]),
                colour,
                dashed,
            );
        }
        if let Some([from, to]) = epipolar.get() {
            let (from, to) = (t.to_canvas(from), t.to_canvas(to));
            // A dark casing under a bright dash: visible on bright and dark images alike.
            let line = |width: f64, colour: &str| {
                ctx.set_line_width(width);
                ctx.set_stroke_style_str(colour);
                ctx.begin_path();
                ctx.move_to(from[0], from[1]);
                ctx.line_to(to[0], to[1]);
                ctx.stroke();
            };
            line(4.5, EPIPOLAR_CASING);
            let dash = js_sys::Array::new();
            dash.push(&8.0.into());
            dash.push(&4.0.into());
            let _ = ctx.set_line_dash(&dash);
            line(2.0, EPIPOLAR_LINE);
            let _ = ctx.set_line_dash(&js_sys::Array::new());
        }
        if let (Some(p), Some(_)) = (pointer.get(), display.tool.get().mask_tool()) {
            let r = display.brush_radius.get() * t.scale;
            ctx.set_line_width(1.5);
            ctx.set_stroke_style_str("rgba(255,255,255,0.9)");
            ctx.begin_path();
            ctx.arc(p[0], p[1], r, 0.0, std::f64::consts::TAU).ok();
            ctx.stroke();
            ctx.set_stroke_style_str("rgba(0,0,0,0.7)");
            ctx.begin_path();
            ctx.arc(p[0], p[1], r + 1.5, 0.0, std::f64::consts::TAU)
                .ok();
            ctx.stroke();
        }
    });

    let canvas_point = move |ev: &web_sys::MouseEvent| -> Option<[f64; 2]> {
        let canvas = canvas.get_untracked()?;
        let rect = canvas.get_bounding_client_rect();
        let k = CANVAS_SIDE / rect.width().max(1.0);
        Some([
            (f64::from(ev.client_x()) - rect.left()) * k,
            (f64::from(ev.client_y()) - rect.top()) * k,
        ])
    };
    let on_down = move |ev: web_sys::PointerEvent| {
        let Some(p) = canvas_point(&ev) else { return };
        ev.prevent_default();
        if let Some(c) = canvas.get_untracked() {
            let _ = c.set_pointer_capture(ev.pointer_id());
        }
        let tool = display.tool.get_untracked();
        match tool.mask_tool() {
            Some(mask_tool) if ev.button() == 0 => {
                if pairs.shown_id().is_none() {
                    return;
                }
                if pairs.showing_draft() {
                    studio.keep_draft();
                }
                let at = transform.get_untracked().to_image(p);
                let radius = display.brush_radius.get_untracked();
                // A view not yet labelled starts from H-Net's mask of it (issue #39).
                let start_from = prediction.with_untracked(|p| {
                    p.as_ref().map(|p| {
                        mask::binarize(match view {
                            View::A => &p.mask_a,
                            View::B => &p.mask_b,
                        })
                    })
                });
                pairs.workspace.update(|ws| {
                    ws.begin_stroke(view, start_from);
                    ws.stroke_to(at, at, radius, mask_tool);
                });
                display.show_label.set(true);
                gesture.set_value(Some(Gesture::Stroke(at)));
            }
            None if tool == PointerTool::WindowLevel && ev.button() == 0 => {
                if pairs.showing_cine_frame() {
                    gesture.set_value(Some(Gesture::Window(p)));
                } else {
                    notices.info("window/level changes a DICOM cine's frames: load one in the DICOM cine tab");
                }
            }
            _ => gesture.set_value(Some(Gesture::Pan(p))),
        }
    };
    let on_move = move |ev: web_sys::PointerEvent| {
        let Some(p) = canvas_point(&ev) else { return };
        pointer.set(Some(p));
        display
            .epipolar_pointer
            .set(Some((view, transform.get_untracked().to_image(p))));
        match gesture.get_value() {
            Some(Gesture::Stroke(last)) => {
                let at = transform.get_untracked().to_image(p);
                let radius = display.brush_radius.get_untracked();
                if let Some(tool) = display.tool.get_untracked().mask_tool() {
                    pairs
                        .workspace
                        .update(|ws| ws.stroke_to(last, at, radius, tool));
                }
                gesture.set_value(Some(Gesture::Stroke(at)));
            }
            Some(Gesture::Pan(last)) => {
                transform.update(|t| {
                    t.offset[0] += p[0] - last[0];
                    t.offset[1] += p[1] - last[1];
                });
                gesture.set_value(Some(Gesture::Pan(p)));
            }
            Some(Gesture::Window(last)) => {
                studio.drag_window(
                    view,
                    (p[0] - last[0]) / CANVAS_SIDE,
                    (p[1] - last[1]) / CANVAS_SIDE,
                );
                gesture.set_value(Some(Gesture::Window(p)));
            }
            None => {}
        }
    };
    let on_up = move |_: web_sys::PointerEvent| {
        match gesture.get_value() {
            Some(Gesture::Stroke(_)) => pairs.edit(|ws| ws.end_stroke()),
            Some(Gesture::Window(_)) => studio.run_model(),
            _ => {}
        }
        gesture.set_value(None);
    };
    let on_wheel = move |ev: web_sys::WheelEvent| {
        let Some(p) = canvas_point(&ev) else { return };
        ev.prevent_default();
        let factor = (-ev.delta_y() * 0.002).exp();
        transform.update(|t| *t = t.zoomed(factor, p));
    };
    // The keyboard on a focused view: arrows pan (a zoomed view), + and - zoom at the centre.
    let on_key = move |ev: web_sys::KeyboardEvent| {
        const STEP: f64 = 24.0;
        let control = ev.ctrl_key() || ev.meta_key();
        let Some(command) = keymap::command(Scope::View, &ev.key(), control, ev.shift_key()) else {
            return;
        };
        let t = transform.get_untracked();
        // Only a zoomed view has somewhere to pan to.
        let zoomed = t.scale > ViewTransform::default().scale * 1.001;
        let pan = |dx: f64, dy: f64| {
            if zoomed {
                ViewTransform {
                    offset: [t.offset[0] + dx, t.offset[1] + dy],
                    ..t
                }
            } else {
                t
            }
        };
        let centre = [CANVAS_SIDE / 2.0; 2];
        let next = match command {
            Command::Left => pan(STEP, 0.0),
            Command::Right => pan(-STEP, 0.0),
            Command::Up => pan(0.0, STEP),
            Command::Down => pan(0.0, -STEP),
            Command::Grow => t.zoomed(1.25, centre),
            Command::Shrink => t.zoomed(0.8, centre),
            _ => return,
        };
        ev.prevent_default();
        transform.set(next);
    };
    let description = move || {
        let masks = match (display.show_prediction.get(), display.show_label.get()) {
            (true, true) => "H-Net's mask in blue and the label in orange",
            (true, false) => "H-Net's mask in blue",
            (false, true) => "the label in orange",
            (false, false) => "no masks shown",
        };
        format!(
            "View {}: the image with {masks}. Paint with the pointer; arrow keys pan and + or - \
             zoom this view.",
            view.letter()
        )
    };
    let label_pixels = move || {
        pairs.with_shown(|p| {
            p.map_or(0, |p| {
                if p.masks_labeled {
                    p.labeled_pixels(view)
                } else {
                    0
                }
            })
        })
    };
    let predicted_pixels = move || {
        prediction.with(|p| {
            p.as_ref().map(|p| {
                let mask = if view == View::A {
                    &p.mask_a
                } else {
                    &p.mask_b
                };
                mask.iter().filter(|&&m| mask::is_catheter(m)).count()
            })
        })
    };

    view! {
        <figure class="view">
            <canvas id=format!("view-{}", view.letter().to_lowercase())
                width=CANVAS_SIDE height=CANVAS_SIDE node_ref=canvas
                class:panning=move || display.tool.get() == PointerTool::Pan
                data-label-pixels=move || label_pixels().to_string()
                data-predicted-pixels=move || predicted_pixels().map(|n| n.to_string()).unwrap_or_default()
                on:pointerdown=on_down on:pointermove=on_move on:pointerup=on_up
                on:pointercancel=on_up on:pointerleave=move |_| {
                    pointer.set(None);
                    if display.epipolar_pointer.get_untracked().is_some_and(|(v, _)| v == view) {
                        display.epipolar_pointer.set(None);
                    }
                }
                data-epipolar=move || epipolar.get().map(|[a, b]| format!("{:.1},{:.1},{:.1},{:.1}", a[0], a[1], b[0], b[1])).unwrap_or_default()
                on:wheel=on_wheel on:contextmenu=|ev| ev.prevent_default()
                tabindex="0" role="img" aria-label=description on:keydown=on_key></canvas>
            <figcaption>
                "View "{view.letter()}
                {move || pairs.with_shown(|p| p.map(|p| match &p.source {
                    PairSource::Upload { view_a, view_b, .. } => format!(" · {}", if view == View::A { view_a } else { view_b }),
                    PairSource::Twin { views, .. } => {
                        let c = if view == View::A { views.a } else { views.b };
                        format!(" · C-arm {:+.0}° / {:+.0}°", c.primary_deg, c.secondary_deg)
                    }
                    PairSource::Dicom { views, frame, .. } => {
                        let c = if view == View::A { views.a } else { views.b };
                        format!(" · frame {} · C-arm {:+.0}° / {:+.0}°", frame + 1, c.primary_deg, c.secondary_deg)
                    }
                }))}
                {move || {
                    let z = transform.get().scale / ViewTransform::default().scale;
                    (z > 1.001).then(|| format!(" · {z:.1}×"))
                }}
                // An empty mask is a label only when the view shows no catheter on purpose.
                <label class="no-catheter">
                    <input id=format!("no-catheter-{}", view.letter().to_lowercase()) type="checkbox"
                        disabled=move || pairs.shown_id().is_none()
                        prop:checked=move || pairs.with_shown(|p| p.is_some_and(|p| p.marked_no_catheter(view)))
                        on:change=move |ev| {
                            let none = event_target_checked(&ev);
                            let Some(id) = studio.labeled_pair_id() else { return };
                            pairs.edit(|ws| ws.mark_no_catheter(&id, view, none).then_some(id.clone()));
                        }/>
                    " No catheter in this view"
                </label>
            </figcaption>
        </figure>
    }
}
