//! What computes the networks' GEMMs (`policy.gemm`, [`GemmSetting`]; docs/ppo.md, "GEMMs"):
//! the forward pass of a layer (rollout and update), and the two backward products (weight and
//! input gradient).
//!
//! - Warp tiles: `policy.py`'s `linear_elu` / `linear` and `mlp_backward.py`'s kernels, each a
//!   shared-memory tile GEMM with its epilogue fused (bias and ELU; bias gradient; ELU
//!   derivative). Plain f32 PTX: needs only the driver.
//! - cuBLAS (`cublasGemmEx`, f32 or TF32 products; src/cuda/blas.rs), then an elementwise
//!   `gemm_epilogue.py` kernel in place: `y = x w` then `bias_elu` / `bias_add`; `dw += x^T dz`
//!   (beta 1: the gradients are cleared, then accumulated, as the tile kernel does) then
//!   `column_sums` for `db`; `g = dz w^T` into a scratch buffer then `elu_input_gradient`.
//!
//! Every call is queued on a stream with no host synchronization, so it records into the
//! rollout's and the update's CUDA graphs like any other launch.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::cuda::{Blas, CudaError, GemmMath, Gpu, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};

use super::NnError;
use super::linear_backward::{
    input_gradient_shape, record_linear_backward_input_elu, record_linear_backward_weight,
    weight_gradient_shape,
};
use super::reduce::{ColumnChunks, GRADIENT_ROWS, record_column_sums};

/// Edge of the output tile of one thread block of `linear_elu` / `linear` (policy.py).
pub const TILE: usize = 64;
/// Threads per tile (policy.py `TILE_THREADS`, the module's block size).
pub const TILE_THREADS: usize = 128;

/// `policy.gemm` (docs/ppo.md, "GEMMs"): cuBLAS comes with the CUDA toolkit, not the driver.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum GemmSetting {
    /// cuBLAS in f32 when libcublas can be loaded, else Warp's tile kernels.
    Auto,
    /// cuBLAS with TF32 tensor-core products when libcublas can be loaded, else Warp's tile
    /// kernels (f32). The default (issue 20: on the H100 the update 5.5 ms instead of 8.2,
    /// the backflip's frames to success unchanged).
    #[default]
    AutoTf32,
    /// Warp's tile kernels (plain f32; needs only the driver).
    Warp,
    /// cuBLAS, f32 arithmetic; an error at setup when libcublas cannot be loaded.
    Cublas,
    /// cuBLAS with TF32 tensor-core products (about 1e-3 relative error); as `cublas`.
    CublasTf32,
}

/// Values per row of an input of `k` values that `gemm` reads fastest: on the cuBLAS path
/// a multiple of 4 f32 (16 bytes; observations of 362 values made cuBLAS pick its `align1`
/// kernels, 22-25 us against 11-12 for the next layer on an H100, Nsight Compute, 2026-11-27),
/// on the Warp path `k`.
pub fn padded_input_width(gemm: &PolicyGemm, k: usize) -> usize {
    if gemm.uses_cublas() {
        k.next_multiple_of(4)
    } else {
        k
    }
}

/// The resolved path of the GEMMs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmPath {
    WarpTiles,
    Cublas(GemmMath),
}

/// The policy's GEMM path and, for cuBLAS, the handle (shared by the rollout's policy, the
/// evaluation's and the update: all record onto the GPU's main stream, one after the other;
/// the critic of concurrent networks has a handle of its own, [`PolicyGemm::separate`]).
#[derive(Clone)]
pub struct PolicyGemm {
    setting: GemmSetting,
    path: GemmPath,
    blas: Option<Arc<Blas>>,
    /// Why `auto` runs Warp tiles (cuBLAS could not be opened).
    fallback: Option<String>,
}

impl std::fmt::Debug for PolicyGemm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PolicyGemm({})", self.describe())
    }
}

impl PolicyGemm {
    /// Warp's tile kernels, whatever the setting.
    pub fn warp_tiles() -> PolicyGemm {
        PolicyGemm {
            setting: GemmSetting::Warp,
            path: GemmPath::WarpTiles,
            blas: None,
            fallback: None,
        }
    }

    /// The path `setting` asks for on `gpu`: `auto` (`auto_tf32`) is cuBLAS with f32 (TF32)
    /// products when libcublas opens, else Warp tiles; `cublas` and `cublas_tf32` are a
    /// [`CudaError::BlasUnavailable`] when it does not. Not inside a capture (cuBLAS allocates its workspace here).
    pub fn open(gpu: &Gpu, setting: GemmSetting) -> Result<PolicyGemm, CudaError> {
        let math = match setting {
            GemmSetting::Warp => return Ok(PolicyGemm::warp_tiles()),
            GemmSetting::Auto | GemmSetting::Cublas => GemmMath::F32,
            GemmSetting::AutoTf32 | GemmSetting::CublasTf32 => GemmMath::Tf32,
        };
        let falls_back = matches!(setting, GemmSetting::Auto | GemmSetting::AutoTf32);
        match Blas::open(gpu) {
            Ok(blas) => Ok(PolicyGemm {
                setting,
                path: GemmPath::Cublas(math),
                blas: Some(blas),
                fallback: None,
            }),
            Err(e) if falls_back => Ok(PolicyGemm {
                setting,
                path: GemmPath::WarpTiles,
                blas: None,
                fallback: Some(match e {
                    CudaError::BlasUnavailable { reason } => reason,
                    other => other.to_string(),
                }),
            }),
            Err(e) => Err(e),
        }
    }

    /// The same path with a cuBLAS handle, and so a workspace, of its own (Warp tiles need
    /// none): for GEMMs recorded into a branch of a graph that may run at the same time as
    /// this one's (the critic's branch beside the actor's, `ppo.concurrent_networks`), which must not share a
    /// workspace. Not inside a capture.
    pub fn separate(&self, gpu: &Gpu) -> Result<PolicyGemm, CudaError> {
        match self.path {
            GemmPath::WarpTiles => Ok(self.clone()),
            GemmPath::Cublas(_) => Ok(PolicyGemm {
                blas: Some(Blas::open(gpu)?),
                ..self.clone()
            }),
        }
    }

    pub fn path(&self) -> GemmPath {
        self.path
    }

    pub fn uses_cublas(&self) -> bool {
        matches!(self.path, GemmPath::Cublas(_))
    }

    /// One line for the setup output, e.g. "cuBLAS 12.8.4, f32 products (policy.gemm =
    /// \"auto\")".
    pub fn describe(&self) -> String {
        let setting = match self.setting {
            GemmSetting::Auto => "auto",
            GemmSetting::AutoTf32 => "auto_tf32",
            GemmSetting::Warp => "warp",
            GemmSetting::Cublas => "cublas",
            GemmSetting::CublasTf32 => "cublas_tf32",
        };
        let path = match (&self.path, &self.blas) {
            (GemmPath::Cublas(math), Some(blas)) => format!(
                "cuBLAS {}, {} products",
                blas.version(),
                match math {
                    GemmMath::F32 => "f32",
                    GemmMath::Tf32 => "TF32",
                }
            ),
            _ => "Warp tiles (f32)".to_owned(),
        };
        match &self.fallback {
            Some(why) => format!("{path} (policy.gemm = \"{setting}\"; cuBLAS: {why})"),
            None => format!("{path} (policy.gemm = \"{setting}\")"),
        }
    }

    fn blas(&self) -> Result<(&Blas, GemmMath), NnError> {
        match (&self.path, &self.blas) {
            (GemmPath::Cublas(math), Some(blas)) => Ok((blas, *math)),
            _ => Err(NnError::Internal(
                "the cuBLAS path has no handle".to_owned(),
            )),
        }
    }

    /// Queues `y = elu(x @ w + b)` (`elu`) or `y = x @ w + b`; x `[M, K]`, w `[K, N]`, b `[N]`,
    /// y `[M, N]`.
    #[allow(clippy::too_many_arguments)]
    pub fn record_linear(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        x: &DeviceArray2<f32>,
        w: &DeviceArray2<f32>,
        b: &DeviceArray<f32>,
        y: &DeviceArray2<f32>,
        elu: bool,
    ) -> Result<(), NnError> {
        let ([m, x_cols], [k, n]) = (x.shape(), w.shape());
        if !self.reads_columns(x_cols, k) || b.shape() != [n] || y.shape() != [m, n] {
            return Err(NnError::Shape(format!(
                "layer of x {:?}, w {:?}, b {:?} into y {:?}: expected x [M, K] (cuBLAS: or rows padded past K), w [K, N], b [N], y [M, N]",
                x.shape(),
                w.shape(),
                b.shape(),
                y.shape()
            )));
        }
        if self.path == GemmPath::WarpTiles {
            let threads = m.div_ceil(TILE) * n.div_ceil(TILE) * TILE_THREADS;
            if elu {
                kernels.linear_elu(stream, threads, x, w, b, y)?;
            } else {
                kernels.linear(stream, threads, x, w, b, y)?;
            }
            return Ok(());
        }
        let (blas, math) = self.blas()?;
        let (xm, wm, ym) = (x.blas_columns(k)?, w.blas_matrix()?, y.blas_matrix()?);
        blas.gemm(stream, xm.plain(), wm.plain(), ym, 0.0, math)?;
        if elu {
            kernels.bias_elu(stream, m * n, b, y)?;
        } else {
            kernels.bias_add(stream, m * n, b, y)?;
        }
        Ok(())
    }

    /// Whether a layer of `k` inputs reads an input of `x_cols` columns: all of them, or on the
    /// cuBLAS path the first `k` of rows padded past them (the update's minibatch: rows of a
    /// multiple of 16 bytes, which cuBLAS's vectorized kernels need; [`padded_input_width`]).
    fn reads_columns(&self, x_cols: usize, k: usize) -> bool {
        x_cols == k || (x_cols > k && self.uses_cublas())
    }

    /// Whether a hidden layer's bias gradient comes with the input gradient of the layer above
    /// ([`PolicyGemm::record_input_gradient_elu`]'s epilogue, the cuBLAS path) rather than with
    /// the layer's own weight gradient (the Warp path's tile kernel).
    pub fn bias_with_input_gradient(&self) -> bool {
        self.uses_cublas()
    }

    /// Queues `dw += x^T dz` and, with `db`, `db += sum_rows dz` (x `[M, K]`, dz `[M, N]`, dw
    /// `[K, N]`, db `[N]`); `target_blocks` sizes the split-K reduction of the Warp path. `db`
    /// is `None` where the input gradient of the layer above added it
    /// ([`PolicyGemm::bias_with_input_gradient`]); the Warp path always needs it.
    #[allow(clippy::too_many_arguments)]
    pub fn record_weight_gradient(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        x: &DeviceArray2<f32>,
        dz: &DeviceArray2<f32>,
        dw: &DeviceArray2<f32>,
        db: Option<&DeviceArray<f32>>,
        target_blocks: usize,
    ) -> Result<(), NnError> {
        if self.path == GemmPath::WarpTiles {
            let db = db.ok_or_else(|| {
                NnError::Internal(
                    "the Warp path's weight gradient adds the bias gradient".to_owned(),
                )
            })?;
            // It checks the shapes itself.
            return record_linear_backward_weight(kernels, stream, x, dz, dw, db, target_blocks);
        }
        let (blas, math) = self.blas()?;
        let k = dw.shape()[0];
        if !self.reads_columns(x.shape()[1], k) {
            return Err(NnError::Shape(format!(
                "weight gradient of x {:?} into dw {:?}: x has fewer columns than dw rows",
                x.shape(),
                dw.shape()
            )));
        }
        if let Some(db) = db {
            weight_gradient_shape(x, dz, dw, db)?;
        }
        let (xm, dzm, dwm) = (x.blas_columns(k)?, dz.blas_matrix()?, dw.blas_matrix()?);
        blas.gemm(stream, xm.transposed(), dzm.plain(), dwm, 1.0, math)?;
        match db {
            Some(db) => record_column_sums(kernels, stream, dz, db),
            None => Ok(()),
        }
    }

    /// Queues `y_prev <- (dz @ w^T) * elu'(y_prev)` in place (dz `[M, N]`, w `[K, N]`, y_prev
    /// `[M, K]`, the ELU output of the layer below). The cuBLAS path writes the product into
    /// `scratch` first (at least M x K values; the Warp path needs none) and adds the column
    /// sums of the new `y_prev`, the layer below's bias gradient, to `db_prev` (`[K]`); the Warp
    /// path leaves `db_prev` to that layer's weight gradient.
    #[allow(clippy::too_many_arguments)]
    pub fn record_input_gradient_elu(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        dz: &DeviceArray2<f32>,
        w: &DeviceArray2<f32>,
        y_prev: &DeviceArray2<f32>,
        scratch: Option<&DeviceArray<f32>>,
        db_prev: &DeviceArray<f32>,
    ) -> Result<(), NnError> {
        if self.path == GemmPath::WarpTiles {
            // It checks the shapes itself.
            return record_linear_backward_input_elu(kernels, stream, dz, w, y_prev);
        }
        let [m, k, _] = input_gradient_shape(dz, w, y_prev)?;
        if db_prev.shape() != [k] {
            return Err(NnError::Shape(format!(
                "bias gradient {:?} of a layer of {k} outputs",
                db_prev.shape()
            )));
        }
        let (blas, math) = self.blas()?;
        let scratch = scratch.ok_or_else(|| {
            NnError::Internal("the cuBLAS input gradient needs a scratch buffer".to_owned())
        })?;
        let product = scratch.view(0, [m, k])?;
        let (dzm, wm, gm) = (dz.blas_matrix()?, w.blas_matrix()?, product.blas_matrix()?);
        blas.gemm(stream, dzm.plain(), wm.transposed(), gm, 0.0, math)?;
        let chunks = ColumnChunks::with_rows(m, k, GRADIENT_ROWS);
        kernels.elu_input_gradient(
            stream,
            chunks.threads,
            &product,
            chunks.rows_per_thread as i32,
            y_prev,
            db_prev,
        )?;
        Ok(())
    }
}
