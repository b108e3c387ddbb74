//! The floating-point cost of one PPO update (docs/ppo.md, "Cost").

use crate::nn::LayerShape;

/// Floating-point operations of one update (multiply and add counted as 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateFlops {
    /// Forward passes of actor and critic over every minibatch row of every epoch, and the
    /// critic over the bootstrap row.
    pub forward: f64,
    /// Weight gradients (`x^T dz`) and input gradients (`dz w^T`, not for the first layer).
    pub backward: f64,
}

impl UpdateFlops {
    /// For networks `actor` and `critic`, `samples` = T x N rows per epoch, `epochs`, and the
    /// `envs` bootstrap rows.
    pub fn of(
        actor: &[LayerShape],
        critic: &[LayerShape],
        samples: usize,
        epochs: usize,
        envs: usize,
    ) -> UpdateFlops {
        let macs = |layers: &[LayerShape]| -> f64 {
            layers.iter().map(|l| (l.inputs * l.outputs) as f64).sum()
        };
        let input_macs =
            |layers: &[LayerShape]| -> f64 { macs(layers) - macs(&layers[..layers.len().min(1)]) };
        let rows = (samples * epochs) as f64;
        UpdateFlops {
            forward: 2.0 * rows * (macs(actor) + macs(critic)) + 2.0 * envs as f64 * macs(critic),
            backward: 2.0
                * rows
                * (macs(actor) + macs(critic) + input_macs(actor) + input_macs(critic)),
        }
    }

    pub fn total(&self) -> f64 {
        self.forward + self.backward
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::mlp_layout;

    #[test]
    fn flops_of_the_baseline_update() {
        let actor = mlp_layout(353, &[400, 200, 100], 28);
        let critic = mlp_layout(353, &[400, 200, 100], 1);
        let f = UpdateFlops::of(&actor, &critic, 32 * 4096, 5, 4096);
        // multiply-adds per row: actor 141200 + 80000 + 20000 + 2800 = 244000, critic 241300;
        // input gradients skip the first layers (141200 each)
        let rows = 32.0 * 4096.0 * 5.0;
        assert_eq!(
            f.forward,
            2.0 * rows * (244000.0 + 241300.0) + 2.0 * 4096.0 * 241300.0
        );
        assert_eq!(
            f.backward,
            2.0 * rows * (244000.0 + 241300.0 + 102800.0 + 100100.0)
        );
        assert!((f.total() / 1e12 - 1.5401).abs() < 1e-4, "{}", f.total());
    }
}
