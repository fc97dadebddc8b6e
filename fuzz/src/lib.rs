//! What the fuzz targets share: the default robot model, loaded once per process.

use std::sync::{Arc, OnceLock};

/// The compiled-in default robot (`config/models/upper_body.xml`), loaded on first use.
pub fn model() -> &'static Arc<sim::model::Model> {
    static MODEL: OnceLock<Arc<sim::model::Model>> = OnceLock::new();
    MODEL.get_or_init(|| {
        Arc::new(sim::config::default_model())
    })
}
