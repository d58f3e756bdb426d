"""The shipped vehicle files (``*.toml``, loaded by :func:`vtoladapt.load_vehicle`) and, beside a file
whose numbers are derived from another simulator's model, the derivation (:mod:`.px4_standard_vtol`)."""
