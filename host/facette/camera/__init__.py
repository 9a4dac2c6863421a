"""facette.camera: RAW decoding and camera backends."""
