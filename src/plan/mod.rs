//! Physics plans: Warp's APIC `.wrp` recordings of MuJoCo Warp calls (one `mj_step`, the
//! kinematics a reset needs), read and validated here and replayed as CUDA graphs.
