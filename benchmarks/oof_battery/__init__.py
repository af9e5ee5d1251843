"""Out-of-family battery of calib's diagnosis (issue 25, item 1).

calib's diagnosis (``calib diagnose``) was validated in family only: data from its own BEM
and its own effect models. This battery makes the data with another code and other forms of
the same physics, and counts how often the diagnosis names the right effect.

Truth
    WISDEM's CCBlade (4.2.9, installed into ``.bench-venv`` by ``benchmarks/ccblade_env.sh``;
    never a calib dependency) on calib's embedded NREL 5-MW with its own polars, exported by
    ``benchmarks/export_rotor.py`` and built by ``benchmarks/ccblade_runner.py``'s
    ``build_rotor`` (as ``bench_ccblade`` does). 63 operating points (the demo campaign's 32
    at 9 rpm and the same at 6 rpm without λ = 3: ``campaign.operating_points``); channels
    ``power``, ``thrust``, ``torque`` and ``hub_flap_moment`` (CCBlade's ``Mb`` is the flap
    moment of one blade about the rotor centre, which is calib's ``hub_flap_moment``; calib's
    ``root_flap_moment`` is about the blade root and differs by ~3.6 %). 1 % Gaussian noise
    (1-σ = 1 % of each channel's RMS, stated in ``_sigma`` columns), seeds 25000 + k.

Hidden effects (``hidden_effects.py``; each a different form from ``calib/effects/``)
    ``rotational_augmentation`` (WISDEM ``Polar.correction3D``, Du-Selig + Eggers, at the
    design tip-speed ratio), ``reynolds_following`` (skin-friction drag ∝ Re^-0.2 and a
    C_L,max loss per decade, at the Reynolds number CCBlade computes per section and point),
    ``uniform_table`` (the same change at one Reynolds-number ratio on every section and
    point), ``leading_edge_erosion`` (linear ramp from r/R 0.6, drag rise and lift-slope loss),
    ``wind_tunnel_blockage`` (exact momentum solution of a rotor in a closed test section,
    area ratio 0.1, iterated with CCBlade's thrust), and ``control`` (no effect).

Set-ups (``campaign.SETUPS``)
    ``rigid``: tilt 0, precone 0, no shear, one sector. ``tilted``: the rotor's 5 deg tilt and
    2.5 deg precone, shear exponent 0.2, 4 sectors. The calib config of each
    (``config_<set-up>.toml``) states the same in ``[model]``.

Modules
    ``campaign`` (definitions, numpy only), ``hidden_effects`` and ``ccblade_truth`` (run in
    ``.bench-venv``), ``generate`` (truth, noisy CSVs, configs, the BEM-vs-CCBlade agreement,
    the committed subset ``tests/data/oof/``), ``runner`` (diagnoses on ≤ 2 processes, the
    rule of "right", tables). Entry point: ``benchmarks/bench_oof_battery.py`` (``make
    validate``), figures in ``bench_output/oof_battery.json`` and ``.md``.

Run
    ``.venv/bin/python benchmarks/bench_oof_battery.py 20`` (the full battery);
    ``.venv/bin/python benchmarks/oof_battery/generate.py --subset tests/data/oof`` (the
    committed subset).
"""
