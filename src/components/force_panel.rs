//! The tip force: H-Net's estimate in newtons, the physics estimate (the rod fitted to the
//! catheter in 3D) and its disagreement with H-Net's, the two combined where the rod was fitted to
//! H-Net's masks, the best of them against the ablation band, the true force and the error for
//! twin pairs; and the pair's force label (typed, accepted from the estimate or the truth, or
//! imported from a CSV file).

use leptos::prelude::*;

use crate::browser::{read_file_with, take_picked_file};
use crate::bundled::BUNDLED_FORCE_CAVEAT;
use crate::catheter_3d::FitMasks;
use crate::engine::Prediction;
use crate::engine::WeightsOrigin;
use crate::error_text::with_causes;
use crate::force_label::{implausible_tip_force, parse_force_labels, parse_newtons};
use crate::force_reading::{ABLATION_BAND_N, BandPosition, Disagreement, Verdict};
use crate::studio::{CatheterReading, ModelState, NetworkStore, Notices, PairStore, Studio};
use hnet_twin::dataset::label_origin::LabelOrigin;
use hnet_twin::reconstruction::physics_force::{EstimateKind, TipForceEstimate};
use hnet_units::TipForce;

/// Full scale of the magnitude gauge, newtons.
const GAUGE_MAX_N: f32 = 0.5;

/// `read` of the reconstruction of the pair on screen, if it was made from the masks the rod is
/// now to be fitted to (a reading from before the choice changed is not shown).
fn shown_reading<T>(
    pairs: PairStore,
    catheter: RwSignal<Option<CatheterReading>>,
    fit_masks: RwSignal<FitMasks>,
    read: impl FnOnce(&CatheterReading) -> Option<T>,
) -> Option<T> {
    let id = pairs.shown_id()?;
    let fit_masks = fit_masks.get();
    catheter.with(|r| {
        r.as_ref()
            .filter(|r| r.id == id && r.fit_masks == fit_masks)
            .and_then(read)
    })
}

/// The force panel.
#[component]
pub fn ForcePanel(
    pairs: PairStore,
    network: NetworkStore,
    /// The catheter in 3D of the pair on screen, once reconstructed.
    catheter: RwSignal<Option<CatheterReading>>,
    /// Which masks the rod is to be fitted to.
    fit_masks: RwSignal<FitMasks>,
    notices: Notices,
    /// H-Net's prediction of the pair on screen.
    prediction: Memo<Option<Prediction>>,
    studio: Studio,
) -> impl IntoView {
    let estimate = move || prediction.with(|p| p.as_ref().and_then(|p| p.force_n));
    let truth = move || pairs.with_shown(|p| p.and_then(|p| p.true_force()));
    // The physics estimate of the pair on screen, if its catheter was reconstructed.
    let physics = move || {
        shown_reading(pairs, catheter, fit_masks, |r| {
            Some(r.result.as_ref().ok()?.force_n)
        })
    };
    let physics_masks = move || {
        shown_reading(pairs, catheter, fit_masks, |r| {
            Some(r.result.as_ref().ok()?.masks)
        })
    };
    // What the loaded weights' force was trained on and how far off it is, when their file
    // records it (hnet_twin::model_facts).
    let domain = move || {
        network.model.with(|m| match m {
            ModelState::Ready(e) => e.domain.clone(),
            _ => None,
        })
    };
    let bundled = move || {
        network
            .model
            .with(|m| matches!(m, ModelState::Ready(e) if e.origin == WeightsOrigin::Bundled))
    };
    // The estimate the gauge and the verdict read, with its 90 % intervals: H-Net's force
    // combined with the physics estimate where the rod was fitted to H-Net's masks, else H-Net's
    // alone; without recorded facts, H-Net's with no interval.
    let combination = move || {
        network.model.with(|m| match m {
            ModelState::Ready(e) => e.combination,
            _ => None,
        })
    };
    // How the pair departs from what the force head was trained on (C-arm angles; a twin
    // pair's catheter and pose): there its force is not shown on its own
    // (`TrainingDomain::head_departures`).
    let head_departures = move || {
        domain()
            .and_then(|d| pairs.with_shown(|p| p.map(|p| d.head_departures(p))))
            .unwrap_or_default()
    };
    let head_shown = move || estimate().filter(|_| head_departures().is_empty());
    // The estimate, or why there is none where it would be the head alone on such a pair.
    let reading_or_why = move || -> Option<Result<TipForceEstimate, String>> {
        let e = estimate()?;
        let physics = shown_reading(pairs, catheter, fit_masks, |r| r.physics_for(e));
        Some(match combination() {
            Some(c) => c.estimate_at(e, physics, &head_departures()),
            None => Ok(TipForceEstimate::uncalibrated(e)),
        })
    };
    let reading = move || reading_or_why().and_then(Result::ok);
    // H-Net's own interval, for its row of the table.
    let head_interval = move || Some(combination()?.head_interval_90_n());
    let label = move || pairs.with_shown(|p| p.and_then(|p| p.force_n));
    // The label being typed, per axis, exactly as typed. The fields show the pair's label when
    // another pair is shown or its label changes, and are never rewritten while typing (a
    // rewrite moves the caret: typing `0.12` used to leave `120`).
    let typed = RwSignal::new([String::new(), String::new(), String::new()]);
    let shown_label = Memo::new(move |_| (pairs.shown_id(), label()));
    let field_text = RwSignal::new([String::new(), String::new(), String::new()]);
    // A typed label far outside a catheter's range, waiting for the user's confirmation.
    let implausible = RwSignal::new(None::<(TipForce, String)>);
    // Shows `force` in the fields, in its shortest exact form (`0.12`, never a rounded `0.123`
    // for `0.12345`, which a save would then write back).
    let show = move |force: Option<TipForce>| {
        let values = force
            .map(|f| f.newtons().map(|v| v.to_string()))
            .unwrap_or_default();
        typed.set(values.clone());
        field_text.set(values);
        implausible.set(None);
    };
    Effect::new(move |_| show(shown_label.get().1));

    let set_label = move |label: Option<(TipForce, LabelOrigin)>| {
        let Some(id) = studio.labeled_pair_id() else {
            return;
        };
        let force = label.as_ref().map(|(f, _)| *f);
        pairs.edit(|ws| ws.set_force(&id, label).then_some(id.clone()));
        // Also when the label was already this value, the fields drop what was being typed.
        show(force);
    };
    // H-Net's estimate as the label, marked as a model's estimate with the weights that made it
    // (the export says so, and `hnet train` leaves it out unless asked).
    let estimate_label = move || {
        let force = head_shown()?;
        let weights = network.model.with(|m| match m {
            ModelState::Ready(e) => Some(e.weights_name.clone()),
            _ => None,
        })?;
        Some((
            force,
            LabelOrigin::Estimate {
                weights,
                estimator: "H-Net".into(),
            },
        ))
    };
    let origin = move || {
        pairs.with_shown(|p| {
            p.filter(|p| p.force_n.is_some())
                .map(|p| p.force_origin.describe())
        })
    };
    let save = move |force: TipForce| {
        implausible.set(None);
        set_label(Some((force, LabelOrigin::Typed)));
        notices.info(format!(
            "force label saved: ({:+.3}, {:+.3}, {:+.3}) N",
            force[0], force[1], force[2]
        ));
    };
    let save_typed = move || {
        let values = typed.get_untracked();
        let mut force = TipForce::ZERO;
        for (axis, text) in values.iter().enumerate() {
            match parse_newtons(TipForce::AXES[axis], text) {
                Ok(v) => force[axis] = v,
                Err(e) => {
                    notices.error(with_causes(&e));
                    return;
                }
            }
        }
        match implausible_tip_force(force) {
            Some(why) => implausible.set(Some((force, why))),
            None => save(force),
        }
    };
    let on_import = move |ev: leptos::ev::Event| {
        let Some(file) = take_picked_file(&ev) else {
            return;
        };
        leptos::task::spawn_local(async move {
            match read_file_with(&file, parse_force_labels).await {
                Ok(labels) => {
                    let mut result = (0, Vec::new());
                    pairs
                        .workspace
                        .update(|ws| result = ws.apply_force_labels(&labels));
                    let ids: Vec<String> = labels.iter().map(|(id, ..)| id.clone()).collect();
                    pairs.persist_metadata(&ids);
                    let (applied, unknown) = result;
                    if unknown.is_empty() {
                        notices.info(format!("{}: {applied} force label(s) applied", file.name()));
                    } else {
                        notices.error(format!(
                            "{}: {applied} force label(s) applied; no pair has the id(s) {}",
                            file.name(),
                            unknown.join(", ")
                        ));
                    }
                }
                Err(e) => notices.error(with_causes(&e)),
            }
        });
    };

    // The verdict says no more than the estimate's intervals and the training data support.
    let verdict_text = move |estimate: TipForceEstimate| {
        let domain = domain();
        pairs.with_shown(|pair| {
            pair.map(|pair| {
                let verdict = Verdict::of(&estimate, domain.as_ref(), pair);
                (
                    format!("{}: {}", estimate.kind.name(), verdict.text(&estimate)),
                    verdict.trust(),
                )
            })
        })
    };
    let cell = |v: f32, interval: Option<f32>| match interval {
        Some(h) => format!("{v:+.3} ± {h:.3}"),
        None => format!("{v:+.3}"),
    };
    let row = move |name: String,
                    values: Option<TipForce>,
                    interval: Option<[f32; 3]>,
                    class: &'static str| {
        view! {
            <tr class=class>
                <th scope="row">{name}</th>
                {(0..3).map(|i| view! {
                    <td>{values.map(|v| cell(v[i], interval.map(|h| h[i]))).unwrap_or_else(|| "–".into())}</td>
                }).collect_view()}
                <td>{values.map(|v| format!("{:.3}", v.magnitude())).unwrap_or_else(|| "–".into())}</td>
            </tr>
        }
    };

    view! {
        <section class="force" aria-labelledby="force-title">
            <h2 id="force-title">"Tip force"</h2>
            // The verdict first, where it is seen without scrolling; the numbers below it.
            {move || reading().map(|r| {
                let m = r.force_n.magnitude();
                let pct = |v: f32| format!("{:.1}%", (v / GAUGE_MAX_N).clamp(0.0, 1.0) * 100.0);
                let range = r.magnitude_range_n();
                let label = match range {
                    Some((low, high)) => format!(
                        "{} estimate {m:.3} N, {low:.3} to {high:.3} N within its 90 % intervals, on a 0 to {GAUGE_MAX_N} N scale",
                        r.kind.name()
                    ),
                    None => format!("{} estimate {m:.3} N on a 0 to {GAUGE_MAX_N} N scale", r.kind.name()),
                };
                view! {
                    <div class="gauge" id="force-gauge" role="img" aria-label=label>
                        <div class="band" style:left=pct(ABLATION_BAND_N[0])
                            style:width=pct(ABLATION_BAND_N[1] - ABLATION_BAND_N[0])></div>
                        // The range of |F| within the estimate's 90 % intervals: a marker in the
                        // band's zone says nothing while its range crosses an edge.
                        {range.map(|(low, high)| view! {
                            <div class="range" id="force-range" style:left=pct(low)
                                style:width=pct(high - low)></div>
                        })}
                        <div class="marker" style:left=pct(m)></div>
                        {truth().map(|t| view! { <div class="marker truth" style:left=pct(t.magnitude())></div> })}
                    </div>
                    {verdict_text(r).map(|(verdict, trust)| view! {
                        <p class="verdict" id="force-verdict" data-estimator=r.kind.name()>{verdict}</p>
                        <p class="trust" id="force-trust">
                            {trust}" "
                            <a href="https://github.com/hnet-studio/hnet-studio/blob/main/docs/clinicians.md"
                                target="_blank" rel="noopener">"What the force can and cannot tell"</a>
                        </p>
                    })}
                    {truth().map(|t| {
                        let m = t.magnitude();
                        view! {
                            <p class="verdict truth" id="force-truth-verdict">
                                {format!("True |F| = {m:.3} N: {}", BandPosition::of(m).phrase())}
                            </p>
                        }
                    })}
                }
            })}
            <table id="force-table">
                <thead><tr><th></th><th>"Fx (N)"</th><th>"Fy (N)"</th><th>"Fz (N)"</th><th>"|F| (N)"</th></tr></thead>
                <tbody>
                    {move || row(
                        if estimate().is_some() && head_shown().is_none() {
                            format!("{} (withheld for this pair)", EstimateKind::Head.name())
                        } else {
                            EstimateKind::Head.name().into()
                        },
                        head_shown(),
                        head_interval(),
                        "estimate",
                    )}
                    // Named by the masks the rod was fitted to: painting a correction changes
                    // them from H-Net's to the labels, and the row says so rather than vanish.
                    {move || row(
                        match physics_masks() {
                            Some(masks) => format!("Physics (rod fit to {})", masks.phrase()),
                            None => "Physics (rod fit)".into(),
                        },
                        physics(),
                        None,
                        "physics",
                    )}
                    // H-Net's and the physics estimate fitted to its masks, combined as the
                    // weights' calibration says: per axis by inverse error variance, or a linear
                    // stack (docs/app.md, "The catheter in 3D and the physics estimate").
                    {move || reading().filter(|r| r.kind == EstimateKind::Combined).map(|r| {
                        row(EstimateKind::Combined.name().into(), Some(r.force_n), r.interval_90_n, "combined")
                    })}
                    {move || truth().map(|t| row("True (twin)".into(), Some(t), None, "truth"))}
                    // The error of the estimate the gauge and the verdict read.
                    {move || match (reading(), truth()) {
                        (Some(r), Some(t)) => Some(row(
                            format!("Error ({})", r.kind.name()),
                            Some(r.force_n - t),
                            None,
                            "error",
                        )),
                        _ => None,
                    }}
                </tbody>
            </table>
            {move || {
                let why = prediction
                    .with(|p| p.as_ref().and_then(|p| p.force_left_out()))
                    .or_else(|| {
                        reading_or_why()?.err().map(|why| format!("No force is read: {why}."))
                    })?;
                Some(view! { <p id="force-left-out" class="why">{why}</p> })
            }}
            {move || match (head_shown(), physics()) {
                (Some(e), Some(p)) => {
                    let d = Disagreement::between(e, p);
                    Some(view! {
                        <p id="force-disagreement" class:warning=d.beyond_tolerance()
                            role=if d.beyond_tolerance() { "alert" } else { "status" }
                            data-delta=format!("{:.4}", d.delta_n)>{d.text()}</p>
                    })
                }
                _ => None,
            }}
            {move || {
                bundled().then(|| view! {
                    <details class="caveat-details">
                        <summary>"Details: how the bundled weights were trained and measured"</summary>
                        <p class="caveat" id="force-caveat">{BUNDLED_FORCE_CAVEAT}</p>
                    </details>
                })
            }}
            <fieldset class="label-force">
                <legend>"Force label of this pair"</legend>
                <form class="typed-force" on:submit=move |ev: leptos::ev::SubmitEvent| {
                    ev.prevent_default();
                    save_typed();
                }>
                    {(0..3).map(|i| view! {
                        <label>{TipForce::AXES[i]}
                            // Text, not type=number: a number field reports "" for partial input
                            // such as `-` or `0.`, which then rewrote what was typed.
                            <input id=format!("label-f{}", ["x", "y", "z"][i]) type="text"
                                inputmode="decimal" autocomplete="off" spellcheck="false"
                                aria-label=format!("{} label in newtons", TipForce::AXES[i])
                                prop:value=move || field_text.with(|t| t[i].clone())
                                on:input=move |ev| {
                                    implausible.set(None);
                                    typed.update(|t| t[i] = event_target_value(&ev));
                                }/>
                            " N"
                        </label>
                    }).collect_view()}
                    <button id="label-save" type="submit" class="primary"
                        disabled=move || pairs.shown_id().is_none()>"Save label"</button>
                </form>
                {move || implausible.get().map(|(force, why)| view! {
                    <div class="confirm" id="label-confirm" role="alertdialog" aria-labelledby="label-confirm-text">
                        <p id="label-confirm-text">{why}</p>
                        <button id="label-confirm-yes" class="danger" on:click=move |_| save(force)>
                            "Save it anyway"
                        </button>
                        <button id="label-confirm-no" on:click=move |_| implausible.set(None)>"Cancel"</button>
                    </div>
                })}
                <div class="actions">
                    <button id="label-from-estimate" disabled=move || estimate_label().is_none()
                        title="Saved as H-Net's estimate, not a measurement: the export marks it, and hnet train leaves it out unless asked"
                        on:click=move |_| set_label(estimate_label())>"Use H-Net's estimate"</button>
                    <button id="label-from-truth" disabled=move || truth().is_none()
                        on:click=move |_| set_label(truth().map(|f| (f, LabelOrigin::Simulated)))>"Use the true force"</button>
                    <button id="label-clear" disabled=move || label().is_none()
                        on:click=move |_| set_label(None)>"Clear"</button>
                    <label class="file-button">"Import CSV…"
                        <input id="label-import" type="file" accept=".csv,text/csv" on:change=on_import/>
                    </label>
                </div>
                <p class="hint">
                    "CSV: a header with id, fx, fy, fz (newtons) and, optionally, label_origin "
                    "(a sensor's log writes measured; without it the labels count as imported); "
                    "other columns are ignored, so a dataset's manifest.csv works. "
                    <span id="label-origin">{move || match origin() {
                        Some(origin) => format!("This pair has a force label: {origin}."),
                        None => "This pair has no force label yet.".to_string(),
                    }}</span>
                </p>
            </fieldset>
        </section>
    }
}
