//! The `pil` image behind the server's policy interface (`frmd serve --firmware`): the served
//! observations and actions arrive as f64 and go to the image as f32, as the host int8 policy
//! takes them.
use super::{ActInput, ServedPolicy};
use crate::firmware::policy::FirmwarePolicy;

impl ServedPolicy for FirmwarePolicy {
    fn reset(&mut self, seed: u64) {
        crate::tasks::Policy::reset(self, seed);
    }

    fn act(&mut self, input: &ActInput<'_>) -> Result<Vec<f64>, String> {
        let narrow = |values: &[f64]| values.iter().map(|&v| v as f32).collect::<Vec<f32>>();
        let obs = narrow(input.obs);
        let chunk = self.chunk(&obs, &narrow(input.prev_action), &narrow(input.prev_rate));
        chunk
            .map(|positions| positions.into_iter().map(f64::from).collect())
            .map_err(|e| format!("{e:#}"))
    }
}
