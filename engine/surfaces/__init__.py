"""Surface scattering models (Lambert, Phong, mirror) behind one interface."""
