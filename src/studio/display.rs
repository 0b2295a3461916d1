//! How the two views are shown and what the pointer does on them: the overlays, the pointer tool
//! and brush, each view's zoom and pan, the pointer whose epipolar line the other view draws,
//! and the open source panel.

use leptos::prelude::*;

use crate::imaging::WORK_SIZE;
use crate::workspace::{Tool, View};

/// What the pointer does on a view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointerTool {
    /// Paints catheter.
    Brush,
    /// Erases catheter.
    Eraser,
    /// Moves the zoomed view.
    Pan,
    /// Changes the window/level of a DICOM frame's plane.
    WindowLevel,
}

impl PointerTool {
    /// The mask tool, for painting tools.
    pub fn mask_tool(self) -> Option<Tool> {
        match self {
            PointerTool::Brush => Some(Tool::Brush),
            PointerTool::Eraser => Some(Tool::Eraser),
            PointerTool::Pan | PointerTool::WindowLevel => None,
        }
    }
}

/// Zoom and pan of one view: screen = `offset + scale · image` in canvas pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewTransform {
    /// Canvas pixels per image pixel.
    pub scale: f64,
    /// Canvas position of the image's top-left corner.
    pub offset: [f64; 2],
}

/// Side of a view's canvas, canvas pixels.
pub const CANVAS_SIDE: f64 = 448.0;

impl Default for ViewTransform {
    /// The fit: a [`WORK_SIZE`] image's longer side across the square canvas.
    fn default() -> Self {
        Self {
            scale: CANVAS_SIDE / WORK_SIZE.width.max(WORK_SIZE.height) as f64,
            offset: [0.0, 0.0],
        }
    }
}

impl ViewTransform {
    /// Image coordinates of a canvas point.
    pub fn to_image(&self, canvas: [f64; 2]) -> [f64; 2] {
        [
            (canvas[0] - self.offset[0]) / self.scale,
            (canvas[1] - self.offset[1]) / self.scale,
        ]
    }

    /// Canvas coordinates of an image point.
    pub fn to_canvas(&self, image: [f64; 2]) -> [f64; 2] {
        [
            self.offset[0] + image[0] * self.scale,
            self.offset[1] + image[1] * self.scale,
        ]
    }

    /// Zooms by `factor` keeping the canvas point `at` fixed (between 1x and 16x the fit).
    pub fn zoomed(&self, factor: f64, at: [f64; 2]) -> Self {
        let fit = Self::default().scale;
        let scale = (self.scale * factor).clamp(fit, 16.0 * fit);
        let image = self.to_image(at);
        Self {
            scale,
            offset: [at[0] - image[0] * scale, at[1] - image[1] * scale],
        }
    }
}

/// Which source panel is open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceTab {
    /// Two image files.
    Images,
    /// A biplane DICOM cine.
    Cine,
    /// The live twin's sliders.
    Twin,
    /// The synthetic X-ray background composer.
    Background,
}

/// How the views are shown and edited.
#[derive(Clone, Copy)]
pub struct DisplaySettings {
    /// Show H-Net's masks.
    pub show_prediction: RwSignal<bool>,
    /// Show the label masks.
    pub show_label: RwSignal<bool>,
    /// Opacity of the mask overlays, 0-1.
    pub opacity: RwSignal<f64>,
    /// What the pointer does.
    pub tool: RwSignal<PointerTool>,
    /// Brush radius, image pixels.
    pub brush_radius: RwSignal<f64>,
    /// Zoom and pan of view A and view B.
    pub transforms: [RwSignal<ViewTransform>; 2],
    /// The open source panel.
    pub tab: RwSignal<SourceTab>,
    /// The pointer on a view (image pixels), whose epipolar line the other view draws.
    pub epipolar_pointer: RwSignal<Option<(View, [f64; 2])>>,
}

impl DisplaySettings {
    /// Both overlays at half opacity, the brush, both views fitted, the images panel open.
    pub fn new() -> Self {
        Self {
            show_prediction: RwSignal::new(true),
            show_label: RwSignal::new(true),
            opacity: RwSignal::new(0.5),
            tool: RwSignal::new(PointerTool::Brush),
            brush_radius: RwSignal::new(3.0),
            transforms: [
                RwSignal::new(ViewTransform::default()),
                RwSignal::new(ViewTransform::default()),
            ],
            tab: RwSignal::new(SourceTab::Images),
            epipolar_pointer: RwSignal::new(None),
        }
    }

    /// Fits both views in their canvases (no zoom, no pan).
    pub fn fit_views(&self) {
        for t in self.transforms {
            t.set(ViewTransform::default());
        }
    }

    /// Zoom and pan of `view`.
    pub fn transform(&self, view: View) -> RwSignal<ViewTransform> {
        self.transforms[view.index()]
    }
}

impl Default for DisplaySettings {
    fn default() -> Self {
        Self::new()
    }
}
