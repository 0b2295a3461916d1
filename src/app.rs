//! The page's top-level component: it creates the [`Studio`] state, loads the model and the
//! saved pairs, installs the keyboard shortcuts and lays out the components.

use leptos::prelude::*;

use crate::components::{
    catheter_view::CatheterView,
    cine_panel::CinePanel,
    composer::Composer,
    fine_tune_panel::FineTunePanel,
    force_panel::ForcePanel,
    force_trace::ForceTracePlot,
    model_bar::ModelBar,
    pair_list::PairList,
    shortcuts::{Shortcuts, install_shortcuts},
    sources::{Sources, TwinSliders, UploadPair},
    stereo_view::StereoView,
};
use crate::engine::WeightsOrigin;
use crate::error_text::with_causes;
use crate::storage;
use crate::studio::{Notices, Stores, Studio, install_reconstruction, load_model};
use crate::workspace::Workspace;

/// The page.
#[component]
pub fn App() -> impl IntoView {
    let stores = Stores::new();
    let Stores {
        notices,
        pairs,
        network,
        display,
        twin,
        cine,
        tuning,
        shown_prediction: prediction,
    } = stores;
    let studio = stores.studio();
    let network_ready = Signal::derive(move || {
        network
            .model
            .with(|m| matches!(m, crate::studio::ModelState::Ready(_)))
    });
    // The catheter calibrated on an earlier visit.
    leptos::task::spawn_local(async move {
        match storage::load_calibration().await {
            Ok(calibration) => {
                if calibration.is_some() && twin.calibration.get_untracked().is_none() {
                    twin.calibration.set(calibration);
                }
            }
            Err(e) => notices.error(format!(
                "The kept catheter calibration could not be read ({}): the stiffness the page assumes is used",
                with_causes(&e)
            )),
        }
    });
    // The weights the user fine-tuned and chose, when the browser keeps some; else the bundled.
    leptos::task::spawn_local(async move {
        match storage::load_kept_weights().await {
            Ok(Some(kept)) => {
                let chosen = kept.chosen.then(|| {
                    (
                        std::rc::Rc::<[u8]>::from(kept.bytes.as_slice()),
                        kept.name.clone(),
                        WeightsOrigin::FineTuned,
                    )
                });
                tuning.kept.set(Some(std::rc::Rc::new(kept)));
                load_model(studio, chosen);
            }
            Ok(None) => load_model(studio, None),
            Err(e) => {
                load_model(studio, None);
                notices.error(format!(
                    "The kept fine-tuned weights could not be read ({}): the bundled weights are used",
                    with_causes(&e)
                ));
            }
        }
    });
    leptos::task::spawn_local(async move {
        match storage::load_pairs().await {
            Ok((saved, damaged)) => {
                if !saved.is_empty() {
                    // Pairs added while storage was being read stay, after the restored ones.
                    pairs.workspace.update(|ws| {
                        let added = std::mem::take(&mut ws.pairs);
                        let mut restored = Workspace::from_pairs(saved);
                        for pair in added {
                            if restored.pair(&pair.id).is_none() {
                                restored.add(pair);
                            }
                        }
                        *ws = restored;
                    });
                    studio.run_model();
                }
                // A first screen that starts somewhere: with nothing saved, a twin pair is on
                // screen at once, with H-Net's masks, force and 3D view once the model is ready.
                if pairs.workspace.with_untracked(|ws| ws.pairs.is_empty())
                    && pairs.draft.with_untracked(Option::is_none)
                {
                    studio.render_twin();
                    studio.run_model();
                }
                if !damaged.is_empty() {
                    notices.error(format!(
                        "{} saved pair(s) could not be read: {}",
                        damaged.len(),
                        damaged
                            .iter()
                            .map(|e| with_causes(e))
                            .collect::<Vec<_>>()
                            .join("; ")
                    ));
                }
            }
            Err(e) => notices.error(format!(
                "saved pairs could not be read: {}",
                with_causes(&e)
            )),
        }
    });
    install_shortcuts(studio, pairs, display);
    install_reconstruction(studio);

    view! {
        <header class="top">
            <h1>"H-Net Studio"</h1>
            <p class="lede">
                "Stereo catheter segmentation and 3D tip-force estimation with H-Net, entirely in "
                "your browser: no image leaves this page. "
                <strong>"Research software, not for clinical use"</strong>
                " (" <a href="https://github.com/hnet-studio/hnet-studio/blob/main/docs/clinicians.md"
                    target="_blank" rel="noopener">"what the force can and cannot tell"</a> ")."
            </p>
            <ModelBar network=network calibration=twin.calibration kept=tuning.kept notices=notices
                prediction=prediction studio=studio/>
        </header>
        <NoticeBar notices=notices studio=studio/>
        <main class="studio">
            <aside class="sources">
                <Sources tab=display.tab studio=studio
                    images=ViewFn::from(move || view! {
                        <UploadPair pairs=pairs notices=notices studio=studio/>
                    })
                    cine=ViewFn::from(move || view! {
                        <CinePanel cine=cine notices=notices tool=display.tool
                            showing_draft=Signal::derive(move || pairs.showing_draft())
                            network_ready=network_ready studio=studio/>
                    })
                    twin=ViewFn::from(move || view! {
                        <TwinSliders twin=twin pairs=pairs studio=studio/>
                    })
                    background=ViewFn::from(move || view! {
                        <Composer twin=twin notices=notices studio=studio/>
                    })/>
            </aside>
            <section class="work">
                <StereoView pairs=pairs display=display notices=notices prediction=prediction studio=studio/>
                // The cine's force trace, as wide as the views, while a cine is loaded.
                {move || cine.player.with(Option::is_some).then(|| view! { <ForceTracePlot cine=cine studio=studio/> })}
                <ForcePanel pairs=pairs network=network catheter=twin.catheter fit_masks=twin.fit_masks
                    notices=notices prediction=prediction studio=studio/>
                <CatheterView pairs=pairs twin=twin notices=notices prediction=prediction studio=studio/>
            </section>
            <aside class="pairs">
                <PairList pairs=pairs notices=notices studio=studio/>
                <FineTunePanel tuning=tuning pairs=pairs notices=notices studio=studio/>
                <Shortcuts/>
            </aside>
        </main>
    }
}

/// The latest message, and the busy state.
#[component]
fn NoticeBar(notices: Notices, studio: Studio) -> impl IntoView {
    view! {
        <div class="notices">
            {move || notices.busy.get().map(|b| view! {
                <p class="busy" id="busy" role="status"><span class="spinner"></span>{b}</p>
            })}
            {move || notices.notice.get().map(|n| view! {
                <p class="notice" id="notice" role=if n.error { "alert" } else { "status" }
                    data-kind=if n.error { "error" } else { "info" }>
                    <span>{n.text}</span>
                    {n.undo.map(|undo| view! {
                        <button id="notice-undo" on:click=move |_| studio.undo_notice(undo.clone())>
                            "Undo"
                        </button>
                    })}
                    <button class="close" title="Dismiss" aria-label="Dismiss this message"
                        on:click=move |_| notices.notice.set(None)>
                        "×"
                    </button>
                </p>
            })}
        </div>
    }
}
