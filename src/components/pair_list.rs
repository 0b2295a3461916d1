//! The labeled pairs (kept in the browser): choose one, delete it, and export the complete ones
//! as a dataset zip that `hnet train` reads.

use leptos::prelude::*;

use crate::browser::{download, yield_to_browser};
use crate::error_text::with_causes;
use crate::export::{DATASET_NAME, ExportBuilder};
use crate::studio::{Notices, PairStore, Studio};
use crate::workspace::PairSource;

/// The pair list.
#[component]
pub fn PairList(pairs: PairStore, notices: Notices, studio: Studio) -> impl IntoView {
    let rows = move || {
        pairs.workspace.with(|ws| {
            ws.pairs
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    (
                        i,
                        p.id.clone(),
                        matches!(p.source, PairSource::Twin { .. }),
                        p.masks_complete(),
                        p.force_n.is_some(),
                        ws.current == Some(i) && !pairs.showing_draft(),
                    )
                })
                .collect::<Vec<_>>()
        })
    };
    let complete = move || {
        pairs
            .workspace
            .with(|ws| ws.pairs.iter().filter(|p| p.is_complete()).count())
    };
    let export = move |_| {
        // Complete pairs without a split get theirs now and keep it from then on.
        let mut assigned = Vec::new();
        pairs.workspace.update(|ws| assigned = ws.assign_splits());
        pairs.persist_metadata(&assigned);
        let planned = pairs
            .workspace
            .with_untracked(|ws| ExportBuilder::new(&ws.pairs));
        let mut builder = match planned {
            Ok(builder) => builder,
            Err(e) => {
                notices.error(with_causes(&e));
                return;
            }
        };
        let ids: Vec<String> = builder.planned().map(str::to_string).collect();
        leptos::task::spawn_local(async move {
            // Pair by pair, letting the browser repaint and take input every few pairs.
            for (index, id) in ids.iter().enumerate() {
                if index % 8 == 0 {
                    notices.busy.set(Some(format!(
                        "Exporting pair {} of {}…",
                        index + 1,
                        ids.len()
                    )));
                    yield_to_browser().await;
                }
                let added = pairs
                    .workspace
                    .with_untracked(|ws| builder.add(index, ws.pair(id)));
                if let Err(e) = added {
                    notices.busy.set(None);
                    notices.error(with_causes(&e));
                    return;
                }
            }
            notices.busy.set(Some("Writing the zip…".into()));
            yield_to_browser().await;
            let result = builder.finish();
            notices.busy.set(None);
            match result {
                Ok(export) => {
                    let name = format!("{DATASET_NAME}.zip");
                    match download(&name, &export.zip, "application/zip") {
                        Ok(()) => {
                            let mut text =
                                format!("{name}: {} pair(s) exported", export.exported.len());
                            if !export.skipped.is_empty() {
                                let skipped: Vec<String> = export
                                    .skipped
                                    .iter()
                                    .map(|(id, why)| format!("{id} ({why})"))
                                    .collect();
                                text.push_str(&format!("; left out: {}", skipped.join(", ")));
                            }
                            match export.split_warning() {
                                Some(warning) => {
                                    notices.error(format!("{text}. Warning: {warning}"))
                                }
                                None => notices.info(text),
                            }
                        }
                        Err(e) => notices.error(with_causes(&e)),
                    }
                }
                Err(e) => notices.error(with_causes(&e)),
            }
        });
    };
    // Deleting asks first; the notice then offers to undo it. The question is about the pair on
    // screen, so it is withdrawn when another pair is shown.
    let confirming = RwSignal::new(false);
    let current_id = Memo::new(move |_| {
        pairs
            .workspace
            .with(|ws| ws.current().map(|p| p.id.clone()))
    });
    Effect::new(move |_| {
        current_id.track();
        confirming.set(false);
    });

    view! {
        <section class="pair-list" aria-labelledby="pairs-title">
            <h2 id="pairs-title">"Labeled pairs"</h2>
            <p class="hint">"Kept in this browser; masks ✓ (a catheter in both, or a view marked as showing none) and force ✓ make a pair complete."</p>
            <ol id="pairs">
                <For each=rows key=|r| r.clone() let:r>
                    <li class:current=r.5 data-id=r.1.clone()>
                        <button class="pair" on:click=move |_| {
                            pairs.draft.set(None);
                            pairs.workspace.update(|ws| ws.select(r.0));
                            studio.run_model();
                        }>
                            <span class="id">{r.1.clone()}</span>
                            <span class="source">{if r.2 { "twin" } else { "images" }}</span>
                            <span class="flag" class:done=r.3 title="masks">"masks"</span>
                            <span class="flag" class:done=r.4 title="force">"force"</span>
                        </button>
                    </li>
                </For>
            </ol>
            <div class="actions">
                <button id="export" class="primary"
                    disabled=move || complete() == 0 || notices.busy.get().is_some() on:click=export>
                    {move || format!("Export {} complete pair(s) (.zip)", complete())}
                </button>
                <button id="calibrate-catheter"
                    title="Fits the catheter's stiffness to the pairs' measured force labels (not H-Net's estimates), each read as the 3D view reads it; at least 3 pairs"
                    disabled=move || pairs.workspace.with(|ws| ws.pairs.iter().all(|p| p.force_n.is_none()))
                    on:click=move |_| studio.calibrate_catheter()>
                    "Calibrate this catheter from labelled pairs"
                </button>
                <button id="delete-pair" disabled=move || current_id.with(Option::is_none) || pairs.showing_draft()
                    aria-expanded=move || confirming.get().to_string()
                    on:click=move |_| confirming.set(true)>"Delete pair…"</button>
            </div>
            {move || current_id.get().filter(|_| confirming.get() && !pairs.showing_draft()).map(|id| view! {
                <div class="confirm" id="delete-confirm" role="alertdialog" aria-labelledby="delete-question">
                    <p id="delete-question">{format!("Delete {id} with its masks and force label?")}</p>
                    <button id="delete-confirm-yes" class="danger" on:click=move |_| {
                        confirming.set(false);
                        studio.delete_current_pair();
                    }>"Delete"</button>
                    <button id="delete-confirm-no" on:click=move |_| confirming.set(false)>"Cancel"</button>
                </div>
            })}
        </section>
    }
}
