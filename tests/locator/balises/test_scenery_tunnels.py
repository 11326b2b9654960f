"""The world's scenery tunnels shade the capture figure (locator.balises.campaign)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from locator.balises.campaign import scenery_tunnel_epochs


def test_scenery_tunnels_are_the_runs_tunnels():
    """A user trial's 200 m recipe tunnel was left unshaded under "grey: tunnel": the figure
    shaded only the track map's tunnels (OpenStreetMap tags), and a world's are its recipe's."""
    spec = {"stretches": [{"kind": "open", "start_m": 0.0, "end_m": 100.0},
                          {"kind": "tunnel", "start_m": 100.0, "end_m": 300.0},
                          {"kind": "open", "start_m": 300.0, "end_m": 500.0}]}  # fmt: skip
    sim = SimpleNamespace(chainage_m=np.array([50.0, 150.0, 300.0, 450.0]),
                          meta={"world_spec": spec})  # fmt: skip
    assert scenery_tunnel_epochs(sim).tolist() == [False, True, True, False]
    assert not scenery_tunnel_epochs(SimpleNamespace(chainage_m=np.zeros(2), meta={})).any()
