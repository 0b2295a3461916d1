//! The C-arm geometry of an uploaded pair: each view's angles and the distances a DICOM header
//! would give, typed by the user ([`StatedGeometry`]). Until they are stated the 3D step assumes
//! the page's default biplane and shows no reprojection check.

use leptos::prelude::*;

use hnet_twin::simulator::carm::Biplane;

use crate::catheter_3d::default_views;
use crate::error_text::with_causes;
use crate::stated_geometry::{GeometryFields, StatedGeometry};

/// The form, for the uploaded pair on screen.
#[component]
pub fn UploadGeometry(
    /// The uploaded pair on screen, its id and its stated C-arms (`None` for other pairs).
    #[prop(into)]
    upload: Signal<Option<(String, Option<Biplane>)>>,
    /// States these C-arms for the pair of that id (`None`: back to the default, assumed).
    on_state: Callback<(String, Option<Biplane>)>,
    /// Reports a value the page cannot use.
    on_error: Callback<String>,
) -> impl IntoView {
    let fields = RwSignal::new(GeometryFields::default());
    // The form shows the pair's stated geometry (or the default) whenever another pair is shown
    // or its geometry changes; never while typing.
    Effect::new(move |_| {
        if let Some((_, views)) = upload.get() {
            let shown = views.unwrap_or_else(default_views);
            fields.set(StatedGeometry::of_views(&shown).fields());
        }
    });
    let apply = move || {
        let Some((id, _)) = upload.get_untracked() else {
            return;
        };
        match StatedGeometry::parse(&fields.get_untracked()) {
            Ok(stated) => on_state.run((id, Some(stated.views()))),
            Err(e) => on_error.run(with_causes(&e)),
        }
    };
    move || {
        upload.get().map(|(_, views)| {
            let stated = views.is_some();
            view! {
                <details class="upload-geometry" id="upload-geometry" open=!stated>
                    <summary>
                        {if stated {
                            "C-arm geometry of this upload: as stated"
                        } else {
                            "C-arm geometry of this upload: not stated (the default frontal and \
                             lateral views are assumed, so the 3D step checks nothing)"
                        }}
                    </summary>
                    <form on:submit=move |ev: leptos::ev::SubmitEvent| {
                        ev.prevent_default();
                        apply();
                    }>
                        {StatedGeometry::FIELDS.iter().enumerate().map(|(i, (label, _))| view! {
                            <label>{*label}
                                <input id=format!("upload-geometry-{i}") type="text" inputmode="decimal"
                                    autocomplete="off" spellcheck="false"
                                    prop:value=move || fields.with(|f| f[i].clone())
                                    on:input=move |ev| fields.update(|f| f[i] = event_target_value(&ev))/>
                            </label>
                        }).collect_view()}
                        <button id="upload-geometry-apply" type="submit" class="primary">
                            "Use this geometry"
                        </button>
                        <button id="upload-geometry-default" type="button" disabled=!stated
                            on:click=move |_| {
                                if let Some((id, _)) = upload.get_untracked() {
                                    on_state.run((id, None));
                                }
                            }>"Back to the default (assumed)"</button>
                    </form>
                    <p class="hint">
                        "Angles as the DICOM header gives them (primary: LAO positive, RAO "
                        "negative; secondary: cranial positive). The distances apply to both "
                        "planes; the detector width is the width the image shows, at the detector."
                    </p>
                </details>
            }
        })
    }
}
