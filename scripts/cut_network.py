"""Cut short stretches of real lines out of a network file into a small network file.

The test and demo network of ``docs/network.md`` (``tests/data/track/network_gembloux.geojson``)
is three 1.5 km stretches around Gembloux cut from Infrabel's whole Belgian network::

    python scripts/cut_network.py \\
        ../shared/data/railway/infrabel/belgium_geovoies_simpl10m.geojson --tolerance-m 10 \\
        --stretch 144:300:1800 161:42500:44000 140:14000:15500 \\
        --out tests/data/track/network_gembloux.geojson

Each ``LINE:FROM_M:TO_M`` keeps the line's reference track (``predisat.track.network``) between
those chainages of its first part: the file's own vertices inside the stretch and the two end
points on the fitted axis. Properties kept: the line id, ``trackname``, ``trackcode``,
``status``; the declared length becomes the stretch's.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from predisat.geodesy import WGS84
from predisat.track.network import Network


def _stretch(text: str) -> tuple[str, float, float]:
    line, a, b = text.rsplit(":", 2)
    return line, float(a), float(b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("network", help="the network GeoJSON to cut from")
    ap.add_argument("--stretch", nargs="+", type=_stretch, required=True,
                    metavar="LINE:FROM_M:TO_M", help="stretches to keep")  # fmt: skip
    ap.add_argument("--tolerance-m", type=float, default=1.0, help="the source's tolerance")
    ap.add_argument("--out", required=True, help="output GeoJSON")
    args = ap.parse_args()
    ids = [s[0] for s in args.stretch]
    net = Network.from_file(args.network, lines=ids, tolerance_m=args.tolerance_m)
    raw = json.loads(Path(args.network).read_text(encoding="utf-8"))
    feats = []
    for lid, a, b in args.stretch:
        ln = net.line(lid)
        tm = ln.parts[0]
        s = tm.project(tm.lat_deg, tm.lon_deg).chainage_m
        inside = (s > a) & (s < b)
        lat0, lon0, _ = tm.position_at(np.array([a, b]))
        lat = np.concatenate([[lat0[0]], tm.lat_deg[inside], [lat0[1]]])
        lon = np.concatenate([[lon0[0]], tm.lon_deg[inside], [lon0[1]]])
        props = raw["features"][ln.features[0]]["properties"]
        keep = {k: props[k] for k in (net.id_key, "trackname", "trackcode", "status") if k in props}
        keep["length"] = round(float(WGS84.line_length(lon, lat)), 3)
        keep["cut_m"] = [a, b]
        coords = [[round(float(x), 7), round(float(y), 7)] for x, y in zip(lon, lat, strict=True)]
        feats.append({"type": "Feature", "properties": keep,
                      "geometry": {"type": "LineString", "coordinates": coords}})  # fmt: skip
        print(f"line {lid}: {a:.0f}-{b:.0f} m of {tm.name}, {len(coords)} vertices, "
              f"{keep['length']:.0f} m")
    doc = {
        "type": "FeatureCollection",
        "name": Path(args.out).stem,
        "source": f"{Path(args.network).name}, stretches cut by scripts/cut_network.py",
        "attribution": raw.get("attribution")
        or "Contains Infrabel open data (opendata.infrabel.be), Infrabel open-data licence",
        "tolerance_m": args.tolerance_m,
        "features": feats,
    }
    Path(args.out).write_text(json.dumps(doc, ensure_ascii=False, indent=1) + "\n",
                              encoding="utf-8")  # fmt: skip


if __name__ == "__main__":
    main()
