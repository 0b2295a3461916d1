//! The model's status: backend, weights and their provenance, the last inference time; choosing
//! the backend and loading other weights.

use std::rc::Rc;

use leptos::prelude::*;

use hnet_model::catheter_entry::EntrySetting;
use hnet_units::mask::MaskAveraging;

use crate::browser::{read_file, take_picked_file};
use crate::catheter_calibration;
use crate::compute::BackendChoice;
use crate::cpu_pool::WorkersStatus;
use crate::engine::Prediction;
use crate::engine::WeightsOrigin;
use crate::error_text::with_causes;
use crate::storage::KeptWeights;
use crate::studio::{ModelState, NetworkStore, Notices, Studio, load_model};
use hnet_twin::model_facts::FACTS_KEY;
use hnet_twin::reconstruction::catalogue::StiffnessCalibration;

/// The model bar.
#[component]
pub fn ModelBar(
    network: NetworkStore,
    /// The catheter's stiffness calibration in use, if any.
    calibration: RwSignal<Option<StiffnessCalibration>>,
    /// The fine-tuned weights kept in the browser, if any.
    kept: RwSignal<Option<std::rc::Rc<KeptWeights>>, LocalStorage>,
    notices: Notices,
    /// H-Net's prediction of the pair on screen.
    prediction: Memo<Option<Prediction>>,
    studio: Studio,
) -> impl IntoView {
    let last_millis = move || {
        prediction.with(|p| {
            p.as_ref().map(|p| match p.workers {
                0 => format!("{:.0} ms on {}", p.millis, p.backend),
                n => format!("{:.0} ms on {}, {n} workers", p.millis, p.backend),
            })
        })
    };
    let on_backend = move |ev: leptos::ev::Event| {
        let choice = BackendChoice::from_value(&event_target_value(&ev));
        network.backend_choice.set(choice);
        // The same weights on the other device.
        let weights = match network.model.get_untracked() {
            ModelState::Ready(engine) => Some((
                engine.weights.clone(),
                engine.weights_name.clone(),
                engine.origin.clone(),
            )),
            _ => None,
        };
        load_model(studio, weights);
    };
    let on_entry = move |ev: leptos::ev::Event| {
        let Some(entry) = EntrySetting::from_text(&event_target_value(&ev)) else {
            return;
        };
        network.catheter_entry.set(entry);
        // Every prediction was read with the previous setting.
        network.predictions.update(|p| p.clear());
        studio.run_model();
    };
    let on_weights = move |ev: leptos::ev::Event| {
        let Some(file) = take_picked_file(&ev) else {
            return;
        };
        leptos::task::spawn_local(async move {
            match read_file(&file).await {
                Ok(bytes) => load_model(
                    studio,
                    Some((Rc::<[u8]>::from(bytes), file.name(), WeightsOrigin::File)),
                ),
                Err(e) => notices.error(with_causes(&e)),
            }
        });
    };

    view! {
        <section id="model-status" class="model-bar" aria-live="polite">
            {move || match network.model.get() {
                ModelState::Loading(text) => view! {
                    <p data-state="loading"><span class="spinner"></span>{text}</p>
                }.into_any(),
                ModelState::Failed(message) => view! {
                    <p data-state="failed" class="error">"H-Net could not be loaded: "{message}</p>
                }.into_any(),
                ModelState::Ready(engine) => {
                    let facts = match &engine.domain {
                        Some(d) => {
                            let [x, y, z] = d.combination.head_interval_90_n();
                            format!(
                                "±{x:.3} / ±{y:.3} / ±{z:.3} N (90 %, force head; trained on {})",
                                d.domain.data
                            )
                        }
                        None => match &engine.facts_error {
                            Some(why) => format!("{why}: no verdict"),
                            None => "not recorded in these weights: no verdict".to_string(),
                        },
                    };
                    let provenance = match engine.origin {
                        WeightsOrigin::Untrained => {
                            "untrained: this build ships no weights (see assets/MODEL.md)".to_string()
                        }
                        _ => engine.header.as_ref().map(|h| {
                            h.provenance.iter()
                                .filter(|(k, _)| k.as_str() != "command" && k.as_str() != FACTS_KEY)
                                .map(|(k, v)| format!("{k}: {v}"))
                                .collect::<Vec<_>>()
                                .join(" · ")
                        }).unwrap_or_default(),
                    };
                    view! {
                        <dl data-state="ready">
                            <div>
                                <dt>"Backend"</dt>
                                <dd id="backend">{engine.backend.label()}</dd>
                                {engine.backend.reason().map(|why| view! {
                                    <dd id="backend-reason" class="why" title=why.to_string()>{format!("({why})")}</dd>
                                })}
                                {engine.check.clone().map(|check| view! {
                                    <dd id="backend-check" class="why">{format!("({check})")}</dd>
                                })}
                                {move || {
                                    let workers = network.cpu_workers.get();
                                    (workers != WorkersStatus::NotUsed).then(|| {
                                        let (short, text) = (workers.short(), workers.text());
                                        view! {
                                            <dd id="cpu-workers" class="why" title=format!(
                                                "{text}. H-Net's views are read off the page's \
                                                 thread, one worker per core the browser \
                                                 reports (at most 8); a worker that stops is \
                                                 replaced and its views read again"
                                            )>{format!("({short})")}</dd>
                                        }
                                    })
                                }}
                            </div>
                            <div><dt>"Parameters"</dt><dd id="params">{engine.params}</dd></div>
                            <div>
                                <dt>"Input"</dt>
                                <dd id="input-size">{format!("{} px", engine.input)}</dd>
                                {(engine.mask_averaging == MaskAveraging::Mirrored).then(|| view! {
                                    <dd id="mask-averaging" class="why" title="Each view is read \
                                        as given and as its left-right mirror image, and the two \
                                        masks averaged, as the weights' calibration was measured \
                                        (hnet eval --mask-averaging mirrored --record): twice the \
                                        network's work. The force head reads the views as given"
                                    >"(each view read twice)"</dd>
                                })}
                            </div>
                            <div>
                                <dt>"Weights"</dt>
                                <dd id="weights" title=provenance>{engine.weights_name.clone()}</dd>
                            </div>
                            <div>
                                <dt>"Force error"</dt>
                                <dd id="force-facts" title=format!(
                                    "{facts}. What the weights file records about its force (hnet \
                                     eval --record): where it was measured and the 90 % intervals \
                                     the verdict reads"
                                )>{facts.clone()}</dd>
                            </div>
                            <div>
                                <dt>"Catheter"</dt>
                                <dd id="catheter-calibration">{move || match calibration.get() {
                                    Some(c) => catheter_calibration::describe(&c),
                                    None => "as the page assumes it (not calibrated)".to_string(),
                                }}</dd>
                                {move || calibration.get().map(|_| view! {
                                    <dd><button id="catheter-calibration-reset" class="link"
                                        on:click=move |_| {
                                            studio.set_calibration(None);
                                            notices.info("catheter calibration cleared: the stiffness the page assumes");
                                        }>"Clear"</button></dd>
                                })}
                            </div>
                            <div>
                                <dt>"Last inference"</dt>
                                <dd id="inference-time">{move || last_millis().unwrap_or_else(|| "–".into())}</dd>
                            </div>
                        </dl>
                    }.into_any()
                }
            }}
            <div class="model-actions">
                <label>
                    "Run on "
                    <select id="backend-choice" on:change=on_backend>
                        {[
                            (BackendChoice::Auto, "Fastest available"),
                            (BackendChoice::WebGpu, "WebGPU"),
                            (BackendChoice::Cpu, "CPU"),
                        ].into_iter().map(|(choice, text)| view! {
                            <option value=choice.value()
                                selected=move || network.backend_choice.get() == choice>{text}</option>
                        }).collect_view()}
                    </select>
                </label>
                <label title="H-Net learned catheters that come up from the bottom of both views. \
                    For one that enters through another edge, each view is turned so that it does \
                    and its masks turned back; H-Net's force is then not read. Finding the edge \
                    reads both views as they are, and the other three turns only of a view whose \
                    catheter does not reach its bottom edge; \u{201c}find it, 4 turns\u{201d} reads all \
                    four turns of both views: four times the time.">
                    "Catheter enters from "
                    <select id="catheter-entry" on:change=on_entry>
                        {[
                            ("bottom", "the bottom (as trained)"),
                            ("auto", "find it"),
                            ("every-turn", "find it, 4 turns"),
                            ("left", "the left"),
                            ("top", "the top"),
                            ("right", "the right"),
                        ].into_iter().map(|(value, text)| view! {
                            <option value=value selected=move || {
                                network.catheter_entry.get().text() == value
                            }>{text}</option>
                        }).collect_view()}
                    </select>
                </label>
                {move || kept.get().map(|kept| {
                    let fine_tuned = move || network.model.with(|m| {
                        matches!(m, ModelState::Ready(e) if e.origin == WeightsOrigin::FineTuned)
                    });
                    view! {
                        <label title="Weights you fine-tuned in this page and kept in this browser">
                            "Weights "
                            <select id="weights-choice" on:change=move |ev| {
                                studio.choose_kept(event_target_value(&ev) == "fine-tuned");
                            }>
                                <option value="bundled" selected=move || !fine_tuned()>"bundled"</option>
                                <option value="fine-tuned" selected=fine_tuned>
                                    {format!("fine-tuned ({})", kept.name)}
                                </option>
                            </select>
                        </label>
                    }
                })}
                <label class="file-button">
                    "Load weights…"
                    <input id="weights-file" type="file" accept=".bpk" on:change=on_weights/>
                </label>
            </div>
        </section>
    }
}
