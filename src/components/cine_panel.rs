//! The DICOM cine source: plane A's and plane B's files (picked or dropped), the twin's sample
//! cine, the player (play, pause, step, scrub), window/level, the force trace over every frame
//! with its progress, cancel and CSV export, and keeping a frame as a labeled pair.

use leptos::prelude::*;

use crate::browser::{download, files, read_file, take_picked_files, yield_to_browser};
use crate::cine::{CinePlayer, GivenFile, SAMPLE_FILES, read_plane, sample_files};
use crate::error_text::with_causes;
use crate::keymap::{Command, tooltip};
use crate::studio::{CineStore, Notices, PointerTool, Studio};
use hnet_dicom::{Plane, PlaneSeries};

/// Reads the bytes of `picked` files; the error names the file.
async fn read_all(picked: Vec<web_sys::File>) -> Result<Vec<GivenFile>, String> {
    let mut given = Vec::with_capacity(picked.len());
    for file in picked {
        match read_file(&file).await {
            Ok(bytes) => given.push((file.name(), bytes)),
            Err(e) => return Err(with_causes(&e)),
        }
    }
    Ok(given)
}

/// The planes read so far, before both are there to be paired.
type PickedPlanes = [Option<PlaneSeries>; 2];

/// Reads `picked` as `plane` into `planes`; once both planes are there, pairs them and loads the
/// cine. A problem is reported naming the file, and only that plane is cleared: a cine already
/// loaded stays.
async fn read_into(
    studio: Studio,
    notices: Notices,
    planes: RwSignal<PickedPlanes, LocalStorage>,
    plane: Plane,
    picked: Vec<web_sys::File>,
) {
    let slot = usize::from(plane == Plane::B);
    let given = match read_all(picked).await {
        Ok(given) => given,
        Err(text) => {
            notices.error(text);
            return;
        }
    };
    notices
        .busy
        .set(Some(format!("Reading plane {}…", plane.name())));
    yield_to_browser().await;
    let read = read_plane(plane, given);
    notices.busy.set(None);
    match read {
        Ok(series) => {
            let name = series.source.clone();
            let frames = series.count();
            let both = planes.try_update(|p| {
                p[slot] = Some(series);
                if p.iter().all(Option::is_some) {
                    let [a, b] = std::mem::take(p);
                    a.zip(b)
                } else {
                    None
                }
            });
            match both.flatten() {
                Some((a, b)) => match CinePlayer::of_planes(a, b) {
                    Ok(player) => studio.load_cine(player),
                    Err(e) => notices.error(with_causes(&e)),
                },
                None => notices.info(format!(
                    "plane {}: {name}, {frames} frames; now give plane {}",
                    plane.name(),
                    ["B", "A"][slot]
                )),
            }
        }
        Err(e) => {
            planes.try_update(|p| p[slot] = None);
            notices.error(with_causes(&e));
        }
    }
}

/// Loads the twin's sample cine through the same reader as any file.
fn load_sample(studio: Studio, notices: Notices) {
    leptos::task::spawn_local(async move {
        notices
            .busy
            .set(Some("Writing a sample cine with the twin…".into()));
        yield_to_browser().await;
        let loaded = sample_files().and_then(|[a, b]| CinePlayer::read(vec![a], vec![b]));
        notices.busy.set(None);
        match loaded {
            Ok(player) => studio.load_cine(player),
            Err(e) => notices.error(with_causes(&e)),
        }
    });
}

/// Offers the sample cine's two files as downloads.
fn download_sample(notices: Notices) {
    match sample_files() {
        Ok(planes) => {
            for (name, bytes) in planes {
                if let Err(e) = download(&name, &bytes, "application/dicom") {
                    notices.error(with_causes(&e));
                    return;
                }
            }
            notices.info(format!("saved {} and {}", SAMPLE_FILES[0], SAMPLE_FILES[1]));
        }
        Err(e) => notices.error(with_causes(&e)),
    }
}

/// The cine tab: loading, then the player.
#[component]
pub fn CinePanel(
    cine: CineStore,
    notices: Notices,
    /// What the pointer does on the views (the window/level tool is chosen here).
    tool: RwSignal<PointerTool>,
    /// Whether the pair on screen is an unsaved draft (a frame that can be kept).
    showing_draft: Signal<bool>,
    /// Whether a network is loaded (the trace needs one).
    network_ready: Signal<bool>,
    studio: Studio,
) -> impl IntoView {
    let planes = RwSignal::new_local([None::<PlaneSeries>, None::<PlaneSeries>]);
    let dragging = RwSignal::new(false);
    // A memo: the player is built when a cine is loaded, not again at every frame or trace step.
    let loaded = Memo::new(move |_| cine.loaded());
    let pick = move |plane: Plane| {
        move |ev: leptos::ev::Event| {
            let picked = take_picked_files(&ev);
            leptos::task::spawn_local(read_into(studio, notices, planes, plane, picked));
        }
    };
    // Two files dropped or picked together: one plane each, the first by name plane A.
    let both = move |mut picked: Vec<web_sys::File>| {
        if picked.len() != 2 {
            notices.error(format!(
                "a biplane cine is two series: give two multi-frame files together (the first by \
                 name is plane A), or each plane's files with its own button; {} file{} given",
                picked.len(),
                if picked.len() == 1 { " was" } else { "s were" }
            ));
            return;
        }
        picked.sort_by_key(|f| f.name());
        let b = picked.pop().into_iter().collect();
        let a = picked;
        leptos::task::spawn_local(async move {
            read_into(studio, notices, planes, Plane::A, a).await;
            read_into(studio, notices, planes, Plane::B, b).await;
        });
    };
    let on_drop = move |ev: leptos::ev::DragEvent| {
        ev.prevent_default();
        dragging.set(false);
        both(files(ev.data_transfer().and_then(|d| d.files())));
    };
    let plane_button = move |plane: Plane, id: &'static str| {
        let slot = usize::from(plane == Plane::B);
        view! {
            <label class="file-button">
                {format!("Plane {}…", plane.name())}
                <input id=id type="file" multiple accept=".dcm,application/dicom,*/*"
                    on:change=pick(plane)/>
                {move || planes.with(|p| p[slot].as_ref().map(|s| view! {
                    <span class="picked">" ✓ "{s.source.clone()}</span>
                }))}
            </label>
        }
    };
    view! {
        <div class="cine">
            <p class="hint">
                "A biplane X-ray cine as DICOM (XA or RF): plane A and plane B, each one \
                 multi-frame file or a series of single frames. Monochrome 8-16 bit, \
                 uncompressed, JPEG or RLE."
            </p>
            {plane_button(Plane::A, "dicom-plane-a")}
            {plane_button(Plane::B, "dicom-plane-b")}
            <div id="dicom-drop-zone" class="drop-zone" class:dragging=move || dragging.get()
                on:dragover=move |ev: leptos::ev::DragEvent| { ev.prevent_default(); dragging.set(true); }
                on:dragleave=move |_| dragging.set(false)
                on:drop=on_drop>
                "…or drop both planes' files here (two multi-frame files; the first by name is plane A)"
            </div>
            <div class="actions">
                <label class="file-button">"Pick both…"
                    <input id="dicom-both" type="file" multiple accept=".dcm,application/dicom,*/*"
                        on:change=move |ev| both(take_picked_files(&ev))/>
                </label>
                <button id="cine-sample" on:click=move |_| load_sample(studio, notices)
                    title="A catheter pushed against the wall and released, rendered by the twin and written as two XA files">
                    "Sample cine from the twin"
                </button>
                <button id="cine-sample-download" class="link" on:click=move |_| download_sample(notices)>
                    "Save the sample as DICOM"
                </button>
            </div>
            <p class="privacy" id="dicom-privacy">
                "DICOM files are read in this page; nothing is uploaded. Kept frames, exported \
                 datasets and force traces carry no patient name, ID, birth date, accession \
                 number or institution: only pixels, the C-arm geometry and frame times are kept."
            </p>
            {move || loaded.get().then(|| view! { <CinePlayerControls cine=cine tool=tool showing_draft=showing_draft network_ready=network_ready studio=studio/> })}
        </div>
    }
}

/// The player, the windows and the trace of the loaded cine.
#[component]
fn CinePlayerControls(
    cine: CineStore,
    tool: RwSignal<PointerTool>,
    showing_draft: Signal<bool>,
    network_ready: Signal<bool>,
    studio: Studio,
) -> impl IntoView {
    let player = cine.player;
    let read =
        move |f: fn(&CinePlayer) -> String| player.with(|c| c.as_ref().map(f).unwrap_or_default());
    let count = move || player.with(|c| c.as_ref().map_or(0, CinePlayer::frame_count));
    let frame = move || player.with(|c| c.as_ref().map_or(0, |c| c.frame));
    let traced = move || player.with(|c| c.as_ref().map_or(0, |c| c.trace().len()));
    // A memo: the buttons below are rebuilt when tracing starts or ends, not at every frame.
    let tracing = Memo::new(move |_| cine.trace_progress.get().is_some());
    let on_scrub = move |ev: leptos::ev::Event| {
        if let Ok(frame) = event_target_value(&ev).parse::<usize>() {
            cine.stop_playback();
            player.update(|c| c.iter_mut().for_each(|c| c.seek(frame)));
            studio.show_cine_frame();
        }
    };
    view! {
        <section class="cine-player" aria-label="Cine player">
            <p class="cine-source" id="cine-source">{move || read(|c| format!(
                "Plane A: {} · plane B: {} · {} frame pairs · {:.1} frames/s",
                c.cine.planes[0].source, c.cine.planes[1].source, c.frame_count(),
                1000.0 / c.frame_interval_ms()
            ))}</p>
            <ul class="cine-notes" id="cine-notes">
                {move || player.with(|c| c.as_ref().map(|c| c.notes.clone()).unwrap_or_default())
                    .into_iter().map(|n| view! { <li>{n}</li> }).collect_view()}
            </ul>
            <div class="actions transport">
                <button id="cine-previous" title=tooltip("Previous frame", Command::PreviousFrame)
                    on:click=move |_| studio.step_cine(-1)>"◀︎ Frame"</button>
                <button id="cine-play" class="primary" title=tooltip("Play or pause", Command::PlayPause)
                    aria-pressed=move || cine.playing.get().to_string()
                    on:click=move |_| studio.toggle_play()>
                    {move || if cine.playing.get() { "Pause" } else { "Play" }}
                </button>
                <button id="cine-next" title=tooltip("Next frame", Command::NextFrame)
                    on:click=move |_| studio.step_cine(1)>"Frame ▶︎"</button>
            </div>
            <label class="slider">
                <span>"Frame"</span>
                <input id="cine-scrub" type="range" min="0" max=move || count().saturating_sub(1)
                    step="1" prop:value=move || frame().to_string()
                    on:input=on_scrub on:change=move |_| studio.run_model()/>
                <output id="cine-frame">{move || read(|c| match c.time_s(c.frame) {
                    Some(t) => format!("frame {} of {} · {t:.3} s", c.frame + 1, c.frame_count()),
                    None => format!("frame {} of {}", c.frame + 1, c.frame_count()),
                })}</output>
            </label>
            <div class="actions">
                <button id="tool-window" class="tool"
                    aria-pressed=move || (tool.get() == PointerTool::WindowLevel).to_string()
                    title=tooltip("Window/level: drag on a view", Command::WindowLevel)
                    on:click=move |_| tool.set(PointerTool::WindowLevel)>"Window/level"</button>
                <button id="cine-window-reset" on:click=move |_| studio.reset_windows()>"Header windows"</button>
                <label title="A drag on either view changes both planes' windows">
                    <input id="cine-link-windows" type="checkbox"
                        prop:checked=move || cine.link_windows.get()
                        on:change=move |ev| cine.link_windows.set(event_target_checked(&ev))/>
                    " Both planes"
                </label>
                <output id="cine-windows">{move || read(|c| format!(
                    "A: C {:.0} W {:.0} · B: C {:.0} W {:.0}",
                    c.windows[0].centre, c.windows[0].width, c.windows[1].centre, c.windows[1].width
                ))}</output>
            </div>
            <div class="actions">
                {move || if tracing.get() {
                    view! {
                        <button id="cine-trace-cancel" on:click=move |_| cine.cancel_trace()>"Stop"</button>
                    }.into_any()
                } else {
                    view! {
                        <button id="cine-trace" class="primary"
                            disabled=move || !network_ready.get()
                            on:click=move |_| studio.trace_cine()>"Trace the force over all frames"</button>
                    }.into_any()
                }}
                {move || cine.trace_progress.get().map(|(done, total)| view! {
                    <progress id="trace-progress" max=total value=done
                        aria-label="Frames traced"></progress>
                    <output>{format!("{done} / {total}")}</output>
                })}
                <button id="cine-export-trace" disabled=move || traced() == 0 || tracing.get()
                    on:click=move |_| studio.export_trace()>"Export trace (CSV)"</button>
                <button id="cine-keep" disabled=move || !showing_draft.get()
                    title="Keep this frame as a labeled pair (label its masks and force, then export)"
                    on:click=move |_| studio.keep_draft()>"Keep this frame"</button>
            </div>
        </section>
    }
}
