//! gb-inpaint: The GB-NeRF pipeline: NeRF reconstruction with BSD appearance and geometry guidance.
