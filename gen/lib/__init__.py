"""The library every Python layer uses: bus topology and load (busload), the one atomic writer
(atomic_output), the one TOML reader (toml_input), the escaping rules (escape: a user's names into
C, DBC, Markdown, HTML, figures, shell and build files), output-folder checks (outdir) and the
repository's paths (paths).

It lives under gen/ because gen/ is already the lowest package (tools/ and host_sim/ import gen,
gen imports neither). gen.lib imports nothing from gen/, host_sim/ or tools/ outside itself, and
no module in gen/ or host_sim/ imports tools/ (tests/python/test_layers.py checks both)."""
