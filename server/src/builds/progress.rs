//! How far the library builds under way have come, by library id: the
//! builder counts into it, the library views read it.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tslg_api::{BuildProgress, LibraryView};
use tslg_method::progress::Progress;

/// The progress of the builds under way, by library id.
#[derive(Default)]
pub struct BuildTracker {
    running: Mutex<HashMap<i64, Arc<Progress>>>,
}

impl BuildTracker {
    pub fn begin(&self, id: i64) -> Arc<Progress> {
        let progress = Arc::new(Progress::default());
        self.lock().insert(id, Arc::clone(&progress));
        progress
    }

    pub fn end(&self, id: i64) {
        self.lock().remove(&id);
    }

    /// Fills the progress of a library being built.
    pub fn fill(&self, view: &mut LibraryView) {
        if let Some(progress) = self.lock().get(&view.id) {
            let (done, total) = progress.get();
            view.progress = Some(BuildProgress { done, total });
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<i64, Arc<Progress>>> {
        self.running.lock().unwrap_or_else(|p| p.into_inner())
    }
}
