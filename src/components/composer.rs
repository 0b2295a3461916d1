//! The synthetic X-ray background composer (paper section II.A): a chest radiograph (the user's
//! or the built-in phantom), a region box dragged over the heart or aorta, its 4x4 patch grid,
//! a seeded shuffle, the XRay-1 / XRay-2 style, and both views' composed backgrounds. The live
//! twin's X-ray pairs are rendered on them.

use hnet_twin::simulator::raster::GreyImage;
use hnet_units::ImageSize;
use leptos::prelude::*;
use wasm_bindgen::{Clamped, JsCast};

use crate::browser::{read_file_with, take_picked_file};
use crate::components::on_slider;
use crate::error_text::with_causes;
use crate::imaging::decode_radiograph;
use crate::keymap::{self, Command, Scope};
use crate::studio::{Notices, Studio, TwinStore};
use crate::twin_live::{XrayBackground, XrayStyle};

/// Side of the radiograph canvas, canvas pixels.
const SOURCE_SIDE: f64 = 320.0;
/// Size of each composed background preview, pixels: square, as style.css shows it.
const PREVIEW_SIZE: ImageSize = ImageSize::square(160);

fn context_2d(canvas: &web_sys::HtmlCanvasElement) -> Option<web_sys::CanvasRenderingContext2d> {
    canvas.get_context("2d").ok()??.dyn_into().ok()
}

/// Puts `image` on `canvas` as 8-bit grey pixels, the canvas sized to it.
fn put_grey(canvas: &web_sys::HtmlCanvasElement, image: &GreyImage) {
    let Some(ctx) = context_2d(canvas) else {
        return;
    };
    let (width, height) = (image.width as u32, image.height as u32);
    canvas.set_width(width);
    canvas.set_height(height);
    let rgba: Vec<u8> = image.to_u8().iter().flat_map(|&g| [g, g, g, 255]).collect();
    if let Ok(data) =
        web_sys::ImageData::new_with_u8_clamped_array_and_sh(Clamped(&rgba), width, height)
    {
        let _ = ctx.put_image_data(&data, 0.0, 0.0);
    }
}

/// Where the radiograph sits on its canvas (letterboxed): offset and size in canvas pixels.
fn placement(bg: &XrayBackground) -> ([f64; 2], [f64; 2]) {
    let (w, h) = (bg.source.image.width as f64, bg.source.image.height as f64);
    let k = SOURCE_SIDE / w.max(h);
    let size = [w * k, h * k];
    (
        [(SOURCE_SIDE - size[0]) / 2.0, (SOURCE_SIDE - size[1]) / 2.0],
        size,
    )
}

/// Draws the patch grid over a `[x0, y0, x1, y1]` box.
fn draw_grid(ctx: &web_sys::CanvasRenderingContext2d, rect: [f64; 4], grid: usize, colour: &str) {
    let [x0, y0, x1, y1] = rect;
    ctx.set_stroke_style_str(colour);
    ctx.set_line_width(1.0);
    for i in 1..grid {
        let t = i as f64 / grid as f64;
        ctx.begin_path();
        ctx.move_to(x0 + t * (x1 - x0), y0);
        ctx.line_to(x0 + t * (x1 - x0), y1);
        ctx.move_to(x0, y0 + t * (y1 - y0));
        ctx.line_to(x1, y0 + t * (y1 - y0));
        ctx.stroke();
    }
    ctx.set_line_width(2.0);
    ctx.stroke_rect(x0, y0, x1 - x0, y1 - y0);
}

/// The composer.
#[component]
pub fn Composer(twin: TwinStore, notices: Notices, studio: Studio) -> impl IntoView {
    let background = twin.background;
    let source_canvas = NodeRef::<leptos::html::Canvas>::new();
    let previews = [
        NodeRef::<leptos::html::Canvas>::new(),
        NodeRef::<leptos::html::Canvas>::new(),
    ];
    // The radiograph as 8-bit grey at canvas size, redrawn only when the source changes.
    let source_pixels = Memo::new(move |_| {
        background.with(|bg| {
            let (_, size) = placement(bg);
            let (w, h) = (size[0].round() as usize, size[1].round() as usize);
            let region = hnet_twin::simulator::raster::Rect([0.0, 0.0, 1.0, 1.0]);
            (
                bg.source.name.clone(),
                w,
                h,
                bg.source.image.crop_resampled(region, w, h).to_u8(),
            )
        })
    });
    let dragging = RwSignal::new(None::<[f64; 2]>);

    Effect::new(move |_| {
        let Some(canvas) = source_canvas.get() else {
            return;
        };
        let Some(ctx) = context_2d(&canvas) else {
            return;
        };
        let (_, w, h, pixels) = source_pixels.get();
        background.with(|bg| {
            let (offset, size) = placement(bg);
            ctx.set_fill_style_str("#111");
            ctx.fill_rect(0.0, 0.0, SOURCE_SIDE, SOURCE_SIDE);
            let rgba: Vec<u8> = pixels.iter().flat_map(|&g| [g, g, g, 255]).collect();
            if let Ok(data) = web_sys::ImageData::new_with_u8_clamped_array_and_sh(
                Clamped(&rgba),
                w as u32,
                h as u32,
            ) {
                let _ = ctx.put_image_data(&data, offset[0].round(), offset[1].round());
            }
            let [x0, y0, x1, y1] = bg.region.0;
            let rect = [
                offset[0] + x0 * size[0],
                offset[1] + y0 * size[1],
                offset[0] + x1 * size[0],
                offset[1] + y1 * size[1],
            ];
            draw_grid(&ctx, rect, bg.rule().grid, "#ffb000");
        });
    });
    Effect::new(move |_| {
        let composed = background.with(|bg| bg.compose(PREVIEW_SIZE));
        let grid = background.with(|bg| bg.rule().grid);
        for (canvas, image) in previews.iter().zip(composed) {
            if let Some(canvas) = canvas.get() {
                put_grey(&canvas, &image);
                if let Some(ctx) = context_2d(&canvas) {
                    let (width, height) = (image.width as f64, image.height as f64);
                    draw_grid(
                        &ctx,
                        [0.0, 0.0, width, height],
                        grid,
                        "rgba(255,176,0,0.55)",
                    );
                }
            }
        }
    });

    // Dragging the region box: the point under the pointer, normalised source coordinates.
    let to_source = move |ev: &web_sys::PointerEvent| -> Option<[f64; 2]> {
        let canvas = source_canvas.get_untracked()?;
        let rect = canvas.get_bounding_client_rect();
        let k = SOURCE_SIDE / rect.width().max(1.0);
        let (x, y) = (
            (f64::from(ev.client_x()) - rect.left()) * k,
            (f64::from(ev.client_y()) - rect.top()) * k,
        );
        let (offset, size) = background.with_untracked(placement);
        Some([(x - offset[0]) / size[0], (y - offset[1]) / size[1]])
    };
    // A new background makes a new twin pair: render it and run H-Net on it.
    let rerender = move || {
        if twin.controls.with_untracked(|t| t.modality.is_xray()) {
            studio.render_twin();
            studio.run_model();
        }
    };
    let on_down = move |ev: web_sys::PointerEvent| {
        let Some(p) = to_source(&ev) else { return };
        let inside = background.with_untracked(|bg| {
            let [x0, y0, x1, y1] = bg.region.0;
            (x0..=x1).contains(&p[0]) && (y0..=y1).contains(&p[1])
        });
        if !inside {
            // A click outside moves the box there.
            background.update(|bg| bg.move_region_to(p));
        }
        let centre = background.with_untracked(|bg| {
            let [x0, y0, x1, y1] = bg.region.0;
            [(x0 + x1) / 2.0, (y0 + y1) / 2.0]
        });
        dragging.set(Some([centre[0] - p[0], centre[1] - p[1]]));
        if let Some(canvas) = source_canvas.get_untracked() {
            let _ = canvas.set_pointer_capture(ev.pointer_id());
        }
    };
    let on_move = move |ev: web_sys::PointerEvent| {
        let (Some(grab), Some(p)) = (dragging.get_untracked(), to_source(&ev)) else {
            return;
        };
        background.update(|bg| bg.move_region_to([p[0] + grab[0], p[1] + grab[1]]));
    };
    let on_up = move |_| {
        if dragging.get_untracked().is_some() {
            dragging.set(None);
            rerender();
        }
    };

    // The keyboard on the focused radiograph: arrows move the region (Shift: five times
    // further), + and - resize it; the pair is made again when the key is released.
    let region_command = |ev: &web_sys::KeyboardEvent| {
        let control = ev.ctrl_key() || ev.meta_key();
        keymap::command(Scope::Region, &ev.key(), control, ev.shift_key())
    };
    // Whether a key moved the region since the pair was last made.
    let moved = StoredValue::new(false);
    let on_key = move |ev: web_sys::KeyboardEvent| {
        let Some(command) = region_command(&ev) else {
            return;
        };
        let step = if ev.shift_key() { 0.05 } else { 0.01 };
        let (dx, dy, grow) = match command {
            Command::Left => (-step, 0.0, 0.0),
            Command::Right => (step, 0.0, 0.0),
            Command::Up => (0.0, -step, 0.0),
            Command::Down => (0.0, step, 0.0),
            Command::Grow => (0.0, 0.0, 0.02),
            Command::Shrink => (0.0, 0.0, -0.02),
            _ => return,
        };
        ev.prevent_default();
        let before = background.with_untracked(|bg| bg.region);
        background.update(|bg| {
            if grow != 0.0 {
                let side = (bg.region_side() + grow).clamp(0.1, 0.8);
                bg.resize_region(side);
            } else {
                let [x0, y0, x1, y1] = bg.region.0;
                bg.move_region_to([(x0 + x1) / 2.0 + dx, (y0 + y1) / 2.0 + dy]);
            }
        });
        if background.with_untracked(|bg| bg.region) != before {
            moved.set_value(true);
        }
    };
    let on_key_up = move |ev: web_sys::KeyboardEvent| {
        if region_command(&ev).is_some() && moved.get_value() {
            moved.set_value(false);
            rerender();
        }
    };
    let on_file = move |ev: leptos::ev::Event| {
        let Some(file) = take_picked_file(&ev) else {
            return;
        };
        leptos::task::spawn_local(async move {
            match read_file_with(&file, decode_radiograph).await {
                Ok(image) => {
                    let (style, seed) = background.with_untracked(|bg| (bg.style, bg.seed));
                    let mut bg = XrayBackground::radiograph(&file.name(), image);
                    bg.style = style;
                    bg.seed = seed;
                    background.set(bg);
                    rerender();
                    notices.info(format!("{} is the background source", file.name()));
                }
                Err(e) => notices.error(with_causes(&e)),
            }
        });
    };
    let set_style = move |style: XrayStyle| {
        background.update(|bg| bg.style = style);
        twin.controls.update(|t| {
            if t.modality.is_xray() {
                t.modality = style.modality();
            }
        });
        rerender();
    };

    view! {
        <div class="composer">
            <p class="hint">
                "As in the paper: a region of a chest X-ray is cut into a 4×4 grid of patches, "
                "shuffled, and the catheter is drawn over it. Drag the box over the heart or aorta."
            </p>
            <div class="actions">
                <button id="background-phantom" on:click=move |_| {
                    let (style, seed) = background.with_untracked(|bg| (bg.style, bg.seed));
                    let mut bg = XrayBackground::phantom();
                    bg.style = style;
                    bg.seed = seed;
                    background.set(bg);
                    rerender();
                }>"Built-in phantom"</button>
                <label class="file-button">"Chest X-ray…"
                    <input id="background-file" type="file" accept="image/png,image/jpeg" on:change=on_file/>
                </label>
            </div>
            <p class="source-name" id="background-source">{move || background.with(|bg| bg.source.description())}</p>
            <canvas id="background-source-canvas" class="source" width=SOURCE_SIDE height=SOURCE_SIDE
                node_ref=source_canvas on:pointerdown=on_down on:pointermove=on_move
                on:pointerup=on_up on:pointercancel=on_up on:keydown=on_key on:keyup=on_key_up
                tabindex="0" role="img"
                aria-label="The radiograph and the region cut into patches: drag the region, or \
                    focus here and move it with the arrow keys (Shift: further), resize it with \
                    + and -"></canvas>
            <label class="slider">
                <span>"Region size"</span>
                <input id="background-region-size" type="range" min="0.1" max="0.8" step="0.01"
                    prop:value=move || background.with(|bg| bg.region_side()).to_string()
                    on:input=on_slider(move |side| background.update(|bg| bg.resize_region(side)))
                    on:change=move |_| rerender()/>
            </label>
            <fieldset class="style">
                <legend>"Style"</legend>
                <label><input type="radio" name="xray-style" id="style-xray1"
                    prop:checked=move || background.with(|bg| bg.style == XrayStyle::Xray1)
                    on:change=move |_| set_style(XrayStyle::Xray1)/>
                    "XRay-1: bright patches (easy)"</label>
                <label><input type="radio" name="xray-style" id="style-xray2"
                    prop:checked=move || background.with(|bg| bg.style == XrayStyle::Xray2)
                    on:change=move |_| set_style(XrayStyle::Xray2)/>
                    "XRay-2: dark and bright patches (hard)"</label>
            </fieldset>
            <div class="actions">
                <label>"Seed "
                    <input id="background-seed" type="number" min="0" step="1"
                        prop:value=move || background.with(|bg| bg.seed).to_string()
                        on:change=move |ev| {
                            if let Ok(seed) = event_target_value(&ev).trim().parse::<u64>() {
                                background.update(|bg| bg.seed = seed);
                                rerender();
                            } else {
                                notices.error("the seed is a whole number ≥ 0");
                            }
                        }/>
                </label>
                <button id="background-shuffle" class="primary" on:click=move |_| {
                    background.update(|bg| bg.seed = bg.seed.wrapping_add(1));
                    rerender();
                }>"Shuffle"</button>
            </div>
            <div class="previews">
                <figure><canvas id="background-a" node_ref=previews[0]></canvas><figcaption>"View A"</figcaption></figure>
                <figure><canvas id="background-b" node_ref=previews[1]></canvas><figcaption>"View B"</figcaption></figure>
            </div>
        </div>
    }
}
