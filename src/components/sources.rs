//! Where pairs come from: two image files (picked or dropped), a biplane DICOM cine
//! ([`CinePanel`](crate::components::cine_panel::CinePanel)), or the live digital twin with its sliders; and the synthetic X-ray background
//! composer.

use hnet_twin::simulator::carm::{SECONDARY_DEG, VIEW_A_PRIMARY_DEG, VIEW_B_PRIMARY_DEG};
use hnet_twin::simulator::scene::Modality;
use hnet_twin::simulator::sensor_plate::PlateContact;
use leptos::prelude::*;

use crate::browser::{PickedFileError, files, read_file_with, take_picked_file, take_picked_files};
use crate::components::on_slider;
use crate::error_text::with_causes;
use crate::imaging::{ImageError, WORK_SIZE, decode_to_rgb};
use crate::keymap::{self, Command, Scope};
use crate::studio::{Notices, PairStore, SourceTab, Studio, TwinStore};
use crate::twin_live::{DEFAULT_PLATE, TwinControls};
use crate::workspace::{LabeledPair, PairSource};

/// The source tabs: which, the tab's element id, its label.
const TABS: [(SourceTab, &str, &str); 4] = [
    (SourceTab::Images, "tab-images", "Images"),
    (SourceTab::Cine, "tab-cine", "DICOM cine"),
    (SourceTab::Twin, "tab-twin", "Digital twin"),
    (SourceTab::Background, "tab-background", "X-ray background"),
];

/// The tabbed source panel. The tabs follow the ARIA tabs pattern with manual activation (a
/// tab's panel renders the twin and runs H-Net, too slow to follow every arrow key): one tab
/// stop, the arrow keys (and Home, End) move the focus between the tabs, Enter or Space opens
/// the focused one.
#[component]
pub fn Sources(
    /// The open tab.
    tab: RwSignal<SourceTab>,
    /// Each tab's panel.
    images: ViewFn,
    cine: ViewFn,
    twin: ViewFn,
    background: ViewFn,
    studio: Studio,
) -> impl IntoView {
    let select = move |which: SourceTab| studio.open_source(which);
    let on_key = move |ev: web_sys::KeyboardEvent| {
        let focused = document()
            .active_element()
            .map(|e| e.id())
            .unwrap_or_default();
        let current = TABS
            .iter()
            .position(|t| t.1 == focused)
            .or_else(|| TABS.iter().position(|t| t.0 == tab.get_untracked()))
            .unwrap_or(0);
        let control = ev.ctrl_key() || ev.meta_key();
        let next = match keymap::command(Scope::Tabs, &ev.key(), control, ev.shift_key()) {
            Some(Command::Right) => (current + 1) % TABS.len(),
            Some(Command::Left) => (current + TABS.len() - 1) % TABS.len(),
            Some(Command::First) => 0,
            Some(Command::Last) => TABS.len() - 1,
            _ => return,
        };
        ev.prevent_default();
        if let Some(button) = document().get_element_by_id(TABS[next].1) {
            let _ = wasm_bindgen::JsCast::unchecked_into::<web_sys::HtmlElement>(button).focus();
        }
    };
    view! {
        <nav class="tabs" role="tablist" aria-label="Where pairs come from" on:keydown=on_key>
            {TABS.into_iter().map(|(which, id, label)| view! {
                <button id=id role="tab" class="tab" aria-controls="source-panel"
                    aria-selected=move || (tab.get() == which).to_string()
                    tabindex=move || if tab.get() == which { "0" } else { "-1" }
                    on:click=move |_| select(which)>
                    {label}
                </button>
            }).collect_view()}
        </nav>
        <div class="tab-panel" id="source-panel" role="tabpanel"
            aria-labelledby=move || TABS.iter().find(|t| t.0 == tab.get()).map_or("", |t| t.1)>
            {move || match tab.get() {
                SourceTab::Images => images.run(),
                SourceTab::Cine => cine.run(),
                SourceTab::Twin => twin.run(),
                SourceTab::Background => background.run(),
            }}
        </div>
    }
}

/// One view's image, decoded at the working size: the file's name and its RGB bytes.
type PickedView = (String, Vec<u8>);

/// Reads and decodes one image file at the working size; the error names the file.
async fn decode_view(file: &web_sys::File) -> Result<PickedView, PickedFileError<ImageError>> {
    read_file_with(file, |name, bytes| {
        Ok((name.to_string(), decode_to_rgb(name, bytes, WORK_SIZE)?))
    })
    .await
}

/// Shows the pair of two decoded views as a draft and runs H-Net on it: it joins the pairs when
/// the user labels it or keeps it, so that images only looked at never fill the list.
fn add_upload(studio: Studio, pairs: PairStore, notices: Notices, [a, b]: [PickedView; 2]) {
    let id = pairs.workspace.with_untracked(|ws| ws.next_id());
    let loaded = format!(
        "{} and {} loaded: label the pair or keep it to add it to your pairs",
        a.0, b.0
    );
    let pair = LabeledPair::new(
        id,
        PairSource::Upload {
            view_a: a.0,
            view_b: b.0,
            views: None,
        },
        a.1,
        b.1,
    );
    notices.info(loaded);
    studio.show_draft(pair);
}

/// Reads two image files (dropped or picked together) into a pair, the first by name as view
/// A. Every problem names its file; nothing is added unless both images are good.
fn load_files(studio: Studio, pairs: PairStore, notices: Notices, mut picked: Vec<web_sys::File>) {
    leptos::task::spawn_local(async move {
        if picked.len() != 2 {
            notices.error(format!(
                "a stereo pair is two images (view A and view B); {} file{} given",
                picked.len(),
                if picked.len() == 1 { " was" } else { "s were" }
            ));
            return;
        }
        picked.sort_by_key(|f| f.name());
        let views = match (decode_view(&picked[0]).await, decode_view(&picked[1]).await) {
            (Ok(a), Ok(b)) => [a, b],
            (Err(e), _) | (_, Err(e)) => {
                notices.error(with_causes(&e));
                return;
            }
        };
        add_upload(studio, pairs, notices, views);
    });
}

/// Two file pickers and a drop zone.
#[component]
pub fn UploadPair(pairs: PairStore, notices: Notices, studio: Studio) -> impl IntoView {
    // Each picker's image is decoded (and any problem reported) as soon as it is picked; the pair
    // is made once both views are there. The reading outlives this panel if the user switches
    // tab meanwhile, so it only touches `picked` while the panel exists.
    let picked = RwSignal::new([None::<PickedView>, None::<PickedView>]);
    let dragging = RwSignal::new(false);
    let pick = move |view: usize| {
        move |ev: leptos::ev::Event| {
            let Some(file) = take_picked_file(&ev) else {
                return;
            };
            leptos::task::spawn_local(async move {
                let letter = ["A", "B"][view];
                let decoded = match decode_view(&file).await {
                    Ok(decoded) => decoded,
                    Err(e) => {
                        picked.try_update(|p| p[view] = None);
                        notices.error(format!("view {letter}: {}", with_causes(&e)));
                        return;
                    }
                };
                let name = decoded.0.clone();
                let Some(both) = picked.try_update(|p| {
                    p[view] = Some(decoded);
                    if p.iter().all(Option::is_some) {
                        let [a, b] = std::mem::take(p);
                        a.zip(b).map(|(a, b)| [a, b])
                    } else {
                        None
                    }
                }) else {
                    return;
                };
                match both {
                    Some(views) => add_upload(studio, pairs, notices, views),
                    None => notices.info(format!(
                        "view {letter}: {name} is ready; now pick view {}",
                        ["B", "A"][view]
                    )),
                }
            });
        }
    };
    let on_drop = move |ev: leptos::ev::DragEvent| {
        ev.prevent_default();
        dragging.set(false);
        let dropped = files(ev.data_transfer().and_then(|d| d.files()));
        load_files(studio, pairs, notices, dropped);
    };
    view! {
        <div class="upload">
            <p class="hint">
                "Two simultaneous images of the catheter (PNG or JPEG, any size; resized to "
                {WORK_SIZE.to_string()}" px). They stay on this machine."
            </p>
            {[0usize, 1].into_iter().map(|view| view! {
                <label class="file-button">
                    {["View A…", "View B…"][view]}
                    <input id=["file-view-a", "file-view-b"][view] type="file"
                        accept="image/png,image/jpeg" on:change=pick(view)/>
                    {move || picked.with(|p| p[view].as_ref().map(|(name, _)| view! {
                        <span class="picked">" ✓ "{name.clone()}</span>
                    }))}
                </label>
            }).collect_view()}
            <div id="drop-zone" class="drop-zone" class:dragging=move || dragging.get()
                on:dragover=move |ev: leptos::ev::DragEvent| { ev.prevent_default(); dragging.set(true); }
                on:dragleave=move |_| dragging.set(false)
                on:drop=on_drop>
                "…or drop both images here (the first by name is view A)"
            </div>
            <label class="file-button">"Pick both…"
                <input id="file-pair" type="file" multiple accept="image/png,image/jpeg"
                    on:change=move |ev| load_files(studio, pairs, notices, take_picked_files(&ev))/>
            </label>
        </div>
    }
}

/// A C-arm angle range (degrees) as a slider's `[min, max, step]`: whole degrees.
fn with_step([min, max]: [f64; 2]) -> [f64; 3] {
    [min, max, 1.0]
}

/// The twin's sliders: each bound to a field of the twin's controls. Moving one re-renders the
/// twin; releasing it runs H-Net.
#[derive(Clone, Copy)]
struct TwinSlider {
    studio: Studio,
    controls: RwSignal<TwinControls>,
}

impl TwinSlider {
    /// One labelled slider over `range` (`[min, max, step]`, in `unit`).
    fn view(
        self,
        id: &'static str,
        label: &'static str,
        unit: &'static str,
        range: [f64; 3],
        get: impl Fn(&TwinControls) -> f64 + Copy + Send + Sync + 'static,
        set: fn(&mut TwinControls, f64),
    ) -> impl IntoView {
        let Self { studio, controls } = self;
        view! {
            <label class="slider">
                <span>{label}</span>
                <input id=id type="range" min=range[0] max=range[1] step=range[2]
                    prop:value=move || controls.with(get).to_string()
                    on:input=on_slider(move |v| {
                        controls.update(|t| set(t, v));
                        studio.render_twin();
                    })
                    on:change=move |_| studio.run_model()/>
                <output>{move || format!("{:.2} {unit}", controls.with(get))}</output>
            </label>
        }
    }
}

/// The twin's sliders.
#[component]
pub fn TwinSliders(twin: TwinStore, pairs: PairStore, studio: Studio) -> impl IntoView {
    let background = twin.background;
    let twin = twin.controls;
    let slider = TwinSlider {
        studio,
        controls: twin,
    };
    let modality = move |ev: leptos::ev::Event| {
        let xray = background.with_untracked(|bg| bg.style.modality());
        twin.update(|t| {
            t.modality = if event_target_value(&ev) == "rgb" {
                Modality::Rgb
            } else {
                xray
            }
        });
        studio.render_twin();
        studio.run_model();
    };
    let scene = move |ev: leptos::ev::Event| {
        twin.update(|t| {
            t.paper_bench = (event_target_value(&ev) == "paper-bench").then_some(DEFAULT_PLATE);
        });
        studio.render_twin();
        studio.run_model();
    };
    let on_bench = move || twin.with(|t| t.paper_bench.is_some());
    // The plate's actuators (only shown on the paper's bench, where they exist).
    let plate = |get: fn(&PlateContact) -> f64| {
        move |t: &TwinControls| t.paper_bench.as_ref().map_or(0.0, get)
    };
    // The force the contact gave, from the draft the sliders rendered.
    let read_force = move || {
        pairs.draft.with(|d| {
            let pair = d.as_ref()?;
            let f = pair.force_n?;
            let PairSource::Twin { settings, .. } = &pair.source else {
                return None;
            };
            let state = settings["scene"]["plate"]["state"]
                .as_str()
                .unwrap_or("free");
            Some(format!(
                "Fx {:.3} N, Fy {:.3} N, Fz {:.3} N, read from the contact ({state})",
                f[0], f[1], f[2]
            ))
        })
    };
    view! {
        <div class="twin">
            <p class="hint">
                "A Kirchhoff rod under a tip force, seen by two C-arm views (world frame: x patient "
                "left, y anterior, z cranial), or the paper's bench: two close-up cameras and the "
                "tip pressed against a sensor plate. The twin's masks and force are exact labels."
            </p>
            <label class="slider">
                <span>"Scene"</span>
                <select id="twin-scene" on:change=scene>
                    <option value="c-arm" selected=move || !on_bench()>"C-arm (clinical framing, a free force)"</option>
                    <option value="paper-bench" selected=on_bench>"The paper's bench (actuated contact)"</option>
                </select>
            </label>
            <Show when=move || !on_bench()>
                <fieldset>
                    <legend>"Tip force"</legend>
                    {slider.view("twin-fx", "Fx", "N", [-0.4, 0.4, 0.01], |t| f64::from(t.force_n[0]), |t, v| t.force_n[0] = v as f32)}
                    {slider.view("twin-fy", "Fy", "N", [-0.4, 0.4, 0.01], |t| f64::from(t.force_n[1]), |t, v| t.force_n[1] = v as f32)}
                    {slider.view("twin-fz", "Fz", "N", [-0.4, 0.4, 0.01], |t| f64::from(t.force_n[2]), |t, v| t.force_n[2] = v as f32)}
                </fieldset>
            </Show>
            <Show when=on_bench>
                <fieldset>
                    <legend>"Sensor plate"</legend>
                    {slider.view("plate-press", "Press", "mm", [0.0, 4.0, 0.05], plate(|c| c.press_mm), |t, v| if let Some(c) = t.paper_bench.as_mut() { c.press_mm = v })}
                    {slider.view("plate-slide", "Slide", "mm", [-3.0, 3.0, 0.05], plate(|c| c.slide_mm), |t, v| if let Some(c) = t.paper_bench.as_mut() { c.slide_mm = v })}
                    {slider.view("plate-slide-direction", "Slide direction", "°", [0.0, 180.0, 1.0], plate(|c| c.slide_azimuth_deg), |t, v| if let Some(c) = t.paper_bench.as_mut() { c.slide_azimuth_deg = v })}
                    {slider.view("plate-tilt", "Plate tilt", "°", [0.0, 30.0, 1.0], plate(|c| c.tilt_deg), |t, v| if let Some(c) = t.paper_bench.as_mut() { c.tilt_deg = v })}
                    {slider.view("plate-tilt-direction", "Tilt direction", "°", [0.0, 360.0, 1.0], plate(|c| c.tilt_azimuth_deg), |t, v| if let Some(c) = t.paper_bench.as_mut() { c.tilt_azimuth_deg = v })}
                    <p id="plate-force" class="hint">{read_force}</p>
                </fieldset>
            </Show>
            <fieldset>
                <legend>"Catheter"</legend>
                {slider.view("twin-stiffness", "Stiffness EI", "mN·m²", [0.3, 1.2, 0.05], |t| t.stiffness_mn_m2, |t, v| t.stiffness_mn_m2 = v)}
                {slider.view("twin-length", "Flexible length", "mm", [30.0, 70.0, 1.0], |t| t.length_mm, |t, v| t.length_mm = v)}
                {slider.view("twin-precurve", "Pre-curve radius (0: straight)", "mm", [0.0, 150.0, 5.0], |t| t.precurve_radius_mm, |t, v| t.precurve_radius_mm = v)}
            </fieldset>
            <fieldset disabled=on_bench>
                <legend>"C-arm"</legend>
                {slider.view("twin-a-primary", "View A LAO/RAO", "°", with_step(VIEW_A_PRIMARY_DEG), |t| t.view_a_deg[0], |t, v| t.view_a_deg[0] = v)}
                {slider.view("twin-a-secondary", "View A cranial/caudal", "°", with_step(SECONDARY_DEG), |t| t.view_a_deg[1], |t, v| t.view_a_deg[1] = v)}
                {slider.view("twin-b-primary", "View B LAO/RAO", "°", with_step(VIEW_B_PRIMARY_DEG), |t| t.view_b_deg[0], |t, v| t.view_b_deg[0] = v)}
                {slider.view("twin-b-secondary", "View B cranial/caudal", "°", with_step(SECONDARY_DEG), |t| t.view_b_deg[1], |t, v| t.view_b_deg[1] = v)}
                <label class="slider">
                    <span>"Images"</span>
                    <select id="twin-modality" on:change=modality>
                        <option value="xray" selected=move || twin.with(|t| t.modality.is_xray())>
                            "X-ray (background from the composer)"
                        </option>
                        <option value="rgb" selected=move || twin.with(|t| !t.modality.is_xray())>
                            "Bench camera (RGB)"
                        </option>
                    </select>
                </label>
            </fieldset>
            <div class="actions">
                <button id="twin-keep" class="primary" disabled=move || !pairs.showing_draft()
                    on:click=move |_| studio.keep_draft()>
                    "Keep this pair"
                </button>
                <button id="twin-reset" on:click=move |_| {
                    twin.set(TwinControls::default());
                    studio.render_twin();
                    studio.run_model();
                }>"Reset"</button>
            </div>
        </div>
    }
}
