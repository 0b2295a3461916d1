//! "Fine-tune on my pairs": start and stop a fine-tune of the loaded network on the page's
//! labelled pairs, its progress, the before/after table on the held-back pairs, and keeping,
//! discarding or downloading the result.

use leptos::prelude::*;

use hnet_model::fine_tune::{FineTuneSettings, HeldBackScores};

use crate::browser::download;
use crate::error_text::with_causes;
use crate::fine_tune::REHEARSAL_PAIRS;
use crate::studio::{
    KEPT_NAME, Notices, PairStore, Studio, TuningProgress, TuningResult, TuningState, TuningStore,
};

/// The panel.
#[component]
pub fn FineTunePanel(
    tuning: TuningStore,
    pairs: PairStore,
    notices: Notices,
    studio: Studio,
) -> impl IntoView {
    let labelled = move || {
        pairs.workspace.with(|ws| {
            let complete = ws.pairs.iter().filter(|p| p.masks_complete()).count();
            (complete, ws.pairs.len())
        })
    };
    let defaults = FineTuneSettings::default();
    let epochs = RwSignal::new(defaults.max_epochs);
    let rehearse = RwSignal::new(true);
    // The share of the starting weights kept, in percent (whole numbers, 0-90).
    let start_percent = RwSignal::new((defaults.start_share * 100.0).round() as u32);
    let about = format!(
        "Trains the loaded network on the pairs whose masks are labels, and its force head on \
         those with a force label (not on labels copied from a model's estimate). Every \
         {}th pair is held back to score the network before and after; the encoders stay as \
         they are; at most {} epochs, stopping when the held-back loss has not improved for {}. \
         The network scored and kept has a share of the starting weights mixed back in, so that \
         it forgets less of what it knew. Runs in workers of its own, one per core (at most \
         two), each step split between them: nothing leaves the browser, and nothing is kept \
         unless you keep it.",
        defaults.hold_back_every, defaults.max_epochs, defaults.patience
    );
    view! {
        <section id="fine-tune" class="fine-tune" aria-live="polite">
            <h2 title=about>"Fine-tune on my pairs"</h2>
            {move || match tuning.state.get() {
                TuningState::Idle => {
                    let (complete, all) = labelled();
                    view! {
                        <p class="hint" id="tune-pairs">
                            {format!("{complete} of {all} pairs have labelled masks")}
                        </p>
                        <label>
                            "At most "
                            <input id="tune-epochs" type="number" min="1" max="100"
                                prop:value=move || epochs.get().to_string()
                                on:change=move |ev| {
                                    if let Ok(n) = event_target_value(&ev).parse::<usize>() {
                                        epochs.set(n.clamp(1, 100));
                                    }
                                }/>
                            " epochs "
                        </label>
                        <label title="Twin pairs drawn from the data the weights were trained on, \
                            trained on beside yours so that the weights do not forget it (when \
                            their file records it)">
                            <input id="tune-rehearse" type="checkbox"
                                prop:checked=move || rehearse.get()
                                on:change=move |ev| rehearse.set(event_target_checked(&ev))/>
                            {format!(" Rehearse on {REHEARSAL_PAIRS} twin pairs of the weights' own domain")}
                        </label>
                        <label title="Every trained weight is moved this far back towards \
                            where it started before the network is scored and kept: more keeps \
                            what the weights knew (measured on 20 blurred pairs: with 15 % the \
                            bench lost 0.013-0.017 of IoU, with none 0.019-0.021), less learns \
                            more of your pairs. 0 keeps the trained weights">
                            "Keep "
                            <input id="tune-start-share" type="number" min="0" max="90" step="5"
                                prop:value=move || start_percent.get().to_string()
                                on:change=move |ev| {
                                    if let Ok(n) = event_target_value(&ev).parse::<u32>() {
                                        start_percent.set(n.min(90));
                                    }
                                }/>
                            " % of the starting weights"
                        </label>
                        <button id="tune-start" on:click=move |_| studio.start_tuning(
                            FineTuneSettings {
                                max_epochs: epochs.get_untracked(),
                                start_share: f64::from(start_percent.get_untracked()) / 100.0,
                                ..FineTuneSettings::default()
                            },
                            rehearse.get_untracked(),
                        )>
                            "Fine-tune on my pairs"
                        </button>
                    }.into_any()
                }
                TuningState::Running(progress) => running(studio, progress).into_any(),
                TuningState::Ended(result) => ended(studio, result).into_any(),
            }}
            {move || tuning.kept.get().map(|kept| {
                let bytes = kept.bytes.clone();
                view! {
                    <p class="hint" id="tune-kept">
                        {format!("Kept in this browser: {} ", kept.name)}
                        <button class="link" id="tune-download" on:click=move |_| {
                            if let Err(e) = download(KEPT_NAME, &bytes, "application/octet-stream") {
                                notices.error(with_causes(&e));
                            }
                        }>"Download"</button>
                    </p>
                }
            })}
        </section>
    }
}

fn running(studio: Studio, p: TuningProgress) -> impl IntoView {
    let max_epochs = p.max_epochs;
    let epoch = p.epochs.len() + 1;
    let loss = p
        .epochs
        .last()
        .map(|e| format!(" · training loss {:.4}", e.train_loss));
    let speed = p.pairs_per_s.map(|r| format!(" · {r:.2} pairs/s"));
    let left = p
        .seconds_left
        .map(|s| format!(" · at most {} left", minutes(s)));
    let workers = format!(" · {}", p.device.describe());
    let what = if p.before.is_none() {
        "Scoring the held-back pairs…".to_string()
    } else {
        format!(
            "Epoch {epoch} of at most {max_epochs} · step {} of {}{}{}{}{workers}",
            p.steps.0,
            p.steps.1,
            loss.unwrap_or_default(),
            speed.unwrap_or_default(),
            left.unwrap_or_default()
        )
    };
    let pairs = if p.before.is_none() {
        format!(
            "{} labelled pairs ({} with a force label). ",
            p.pairs, p.with_force
        )
    } else {
        let rehearsed = match p.rehearsed {
            0 => String::new(),
            n => format!(" and {n} twin pairs rehearsed"),
        };
        format!(
            "{} of your pairs trained on{rehearsed}, {} held back ({} with a force label). ",
            p.split.0.saturating_sub(p.rehearsed),
            p.split.1,
            p.with_force
        )
    };
    view! {
        <p id="tune-progress-text">{pairs}{what}</p>
        <progress id="tune-progress" max=p.steps.1.max(1) value=p.steps.0></progress>
        <button id="tune-stop" on:click=move |_| studio.stop_tuning()>"Stop"</button>
    }
}

fn ended(studio: Studio, r: TuningResult) -> impl IntoView {
    let after = r.best.map(|b| b.held_back);
    let row = |name: &'static str, value: fn(&HeldBackScores) -> Option<String>| {
        let before = value(&r.before).unwrap_or_else(|| "–".into());
        let after = after
            .as_ref()
            .and_then(value)
            .unwrap_or_else(|| "no better epoch".into());
        view! { <tr><th scope="row">{name}</th><td>{before}</td><td>{after}</td></tr> }
    };
    let epoch = r
        .best
        .map(|b| format!(" (epoch {} of {})", b.epoch, r.epochs.len()));
    let keepable = r.weights.is_some();
    view! {
        <table id="tune-table" class="tune-table">
            <caption>{format!("On the {} held-back pairs", r.split.1)}{epoch}</caption>
            <thead><tr><th></th><th>"Before"</th><th>"After"</th></tr></thead>
            <tbody>
                {row("Catheter IoU", |s| Some(format!("{:.3}", s.catheter_iou)))}
                {row("Force MAE", |s| s.force_mae_n.map(|m| format!("{m:.3} N ({} pairs)", s.force_pairs)))}
                {row("Loss", |s| Some(format!("{:.4}", s.loss)))}
            </tbody>
        </table>
        {match (r.before_reference, r.best.and_then(|b| b.reference)) {
            (Some(before), after) => view! {
                <p id="tune-reference" class="hint" title="Twin pairs drawn from the data the \
                    weights were trained on (their recorded domain), never trained on: what \
                    fine-tuning costs there">
                    {format!(
                        "On {} twin pairs of the weights' own domain: catheter IoU {:.3} before, {} after",
                        before.pairs,
                        before.catheter_iou,
                        after.map_or("–".to_string(), |a| format!("{:.3}", a.catheter_iou)),
                    )}
                </p>
            }.into_any(),
            (None, _) => view! {
                <p id="tune-reference" class="hint">
                    "The weights record no twin domain of their own: what fine-tuning costs there is not measured here."
                </p>
            }.into_any(),
        }}
        <div class="tune-actions">
            <button id="tune-keep" disabled=!keepable on:click=move |_| studio.keep_tuned()>
                "Keep and use"
            </button>
            <button id="tune-discard" on:click=move |_| studio.discard_tuned()>"Discard"</button>
        </div>
    }
}

/// `seconds` as minutes and seconds.
fn minutes(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    format!("{}:{:02}", s / 60, s % 60)
}
