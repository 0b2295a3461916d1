//! The labeled pairs (kept in the browser): choose one, delete it, and export the complete ones
//! as a dataset zip that `hnet train` reads.

use leptos::prelude::*;

use crate::app::Studio;
use crate::browser::download;
use crate::export::{DATASET_NAME, dataset_zip};
use crate::storage;
use crate::workspace::PairSource;

/// The pair list.
#[component]
pub fn PairList() -> impl IntoView {
    let studio = expect_context::<Studio>();
    let rows = move || {
        studio.workspace.with(|ws| {
            ws.pairs
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    (
                        i,
                        p.id.clone(),
                        matches!(p.source, PairSource::Twin { .. }),
                        p.masks_labeled,
                        p.force_n.is_some(),
                        ws.current == Some(i) && !studio.showing_draft(),
                    )
                })
                .collect::<Vec<_>>()
        })
    };
    let complete = move || {
        studio
            .workspace
            .with(|ws| ws.pairs.iter().filter(|p| p.is_complete()).count())
    };
    let export = move |_| {
        let result = studio.workspace.with_untracked(|ws| dataset_zip(&ws.pairs));
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
                        studio.info(text);
                    }
                    Err(e) => studio.error(e),
                }
            }
            Err(e) => studio.error(e.to_string()),
        }
    };
    let delete = move |_| {
        let mut removed = None;
        studio.draft.set(None);
        studio.workspace.update(|ws| removed = ws.remove_current());
        if let Some(id) = removed {
            studio.predictions.update(|p| {
                p.remove(&id);
            });
            leptos::task::spawn_local(async move {
                match storage::delete_pair(&id).await {
                    Ok(()) => studio.info(format!("{id} deleted")),
                    Err(e) => studio.error(format!("{id}: not deleted from the browser: {e}")),
                }
            });
        }
    };

    view! {
        <section class="pair-list" aria-labelledby="pairs-title">
            <h2 id="pairs-title">"Labeled pairs"</h2>
            <p class="hint">"Kept in this browser; masks ✓ and force ✓ make a pair complete."</p>
            <ol id="pairs">
                <For each=rows key=|r| r.clone() let:r>
                    <li class:current=r.5 data-id=r.1.clone()>
                        <button class="pair" on:click=move |_| {
                            studio.draft.set(None);
                            studio.workspace.update(|ws| ws.select(r.0));
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
                <button id="export" class="primary" disabled=move || complete() == 0 on:click=export>
                    {move || format!("Export {} complete pair(s) (.zip)", complete())}
                </button>
                <button id="delete-pair" disabled=move || studio.workspace.with(|ws| ws.current.is_none()) || studio.showing_draft()
                    on:click=delete>"Delete pair"</button>
            </div>
        </section>
    }
}
