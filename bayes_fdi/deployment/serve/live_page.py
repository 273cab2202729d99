"""The live page of ``serve``: each valve's last hour, status ribbon and alarms, live.

`LiveHub` keeps, per valve, the last ``history_seconds`` of its records in engineering units
(measured X and F, their validated values and uncertainty bands, the status, the diagnosed fault
and its probability) and the alarm list (an alarm is a detection: it opens when DD rises, shows
the fault or group it is isolated as and its probability while it lasts, and closes when DD
falls; a BLIND second is no alarm). After a restart `LiveHub.load` puts the log's last hour back
in front of the new records. `live_app` is the Starlette application:

- ``/``: the page (``?valve=NAME`` draws one valve; the overview draws the first ``panels``);
- ``/api/state``: the history and alarms as JSON (what the page draws first);
- ``/events``: server-sent events, one message a second with the new records and the alarms;
- ``/static/plotly.min.js``: plotly.js as shipped inside the ``plotly`` Python package (the page
  needs no network).

The charts are plotly.js's (``Plotly.react``); the page's own script only feeds them (a second
missing from the records breaks the lines and the VMV +- VU band there). Served by uvicorn in
``serve``'s event loop, on 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
from collections import deque
from collections.abc import AsyncIterator, Mapping
from typing import Any

import numpy as np

from bayes_fdi.datasets.units import to_physical

__all__ = ["LiveHub", "live_app", "plotly_js_path"]

_FIELDS = ("t", "X", "F", "X_vmv", "X_vu", "F_vmv", "F_vu", "status", "state", "p", "DD")
_FLOATS = ("X", "F", "X_vmv", "X_vu", "F_vmv", "F_vu", "p")
_RECORD_COLUMNS = ("X", "F", "VMV_X", "VU_X", "VMV_F", "VU_F", "status", "state", "probability")
_RECORD_COLUMNS += ("DD",)
_MAX_ALARMS = 200


def plotly_js_path() -> str:
    """The plotly.js file shipped in the ``plotly`` package."""
    import plotly

    path = os.path.join(os.path.dirname(plotly.__file__), "package_data", "plotly.min.js")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"plotly.min.js not found in the plotly package ({path})")
    return path


def _clean(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _scalar(v: Any) -> Any:
    """A numpy scalar as the Python value (the object columns hold Python values already)."""
    return v.item() if isinstance(v, np.generic) else v


def _json_floats(values: np.ndarray) -> list[float | None]:
    """Floats for JSON: NaN and infinities as None."""
    return [v if math.isfinite(v) else None for v in values.tolist()]


class _History:
    """The last ``size`` points of one valve, column by column (ring buffers)."""

    def __init__(self, size: int) -> None:
        self.size, self.n, self.head = int(size), 0, 0
        self.columns: dict[str, np.ndarray] = {"t": np.zeros(self.size, dtype=np.int64)}
        self.columns |= {k: np.full(self.size, np.nan) for k in _FLOATS}
        self.columns |= {k: np.empty(self.size, dtype=object) for k in ("status", "state")}
        self.columns["DD"] = np.zeros(self.size, dtype=bool)

    def append(self, point: Mapping[str, Any]) -> None:
        for k, column in self.columns.items():
            value = point[k]
            column[self.head] = np.nan if value is None else value
        self.head = (self.head + 1) % self.size
        self.n = min(self.n + 1, self.size)

    def ordered(self) -> dict[str, np.ndarray]:
        """The columns, oldest point first."""
        index = (self.head - self.n + np.arange(self.n)) % self.size
        return {k: v[index] for k, v in self.columns.items()}

    def replace(self, columns: Mapping[str, np.ndarray]) -> None:
        """Hold the last ``size`` points of ``columns`` (oldest first) instead."""
        m = min(len(columns["t"]), self.size)
        for k, column in self.columns.items():
            column[:m] = np.asarray(columns[k])[len(columns["t"]) - m :]
        self.n, self.head = m, m % self.size

    def as_json(self) -> dict[str, list[Any]]:
        cols = self.ordered()
        out: dict[str, list[Any]] = {"t": cols["t"].tolist()}
        out |= {k: _json_floats(cols[k]) for k in _FLOATS}
        out |= {k: [str(v) for v in cols[k]] for k in ("status", "state")}
        out["DD"] = cols["DD"].tolist()
        return {k: out[k] for k in _FIELDS}


class LiveHub:
    """The live page's data (see the module docstring)."""

    def __init__(
        self, valves: Mapping[str, Mapping[str, str]], history_seconds: int = 3600, panels: int = 8
    ) -> None:
        self.units = {v: dict(u) for v, u in valves.items()}
        self.panels = int(panels)
        self.history = {v: _History(history_seconds) for v in self.units}
        self.fresh: dict[str, list[dict[str, Any]]] = {v: [] for v in self.units}
        self.alarms: deque[dict[str, Any]] = deque(maxlen=_MAX_ALARMS)
        self.active: dict[str, dict[str, Any]] = {}
        self.queues: set[asyncio.Queue] = set()
        self.sent = 0

    def _points(self, valve: str, rows: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Columns of points in engineering units from record columns (arrays or scalars)."""
        units = self.units[valve]

        def phys(c: str, v: Any) -> np.ndarray:
            return np.asarray(to_physical(np.asarray(v, dtype=np.float64), c, units[c]))

        def width(c: str, centre: Any, half: Any) -> np.ndarray:
            centre = np.asarray(centre, dtype=np.float64)
            return phys(c, centre + np.asarray(half, dtype=np.float64)) - phys(c, centre)

        return {
            "t": np.asarray(rows["time"], dtype=np.int64) * 1000,
            "X": phys("X", rows["X"]),
            "F": phys("F", rows["F"]),
            "X_vmv": phys("X", rows["VMV_X"]),
            "X_vu": width("X", rows["VMV_X"], rows["VU_X"]),
            "F_vmv": phys("F", rows["VMV_F"]),
            "F_vu": width("F", rows["VMV_F"], rows["VU_F"]),
            "status": np.asarray(rows["status"]).astype(str),
            "state": np.asarray(rows["state"]).astype(str),
            "p": np.asarray(rows["probability"], dtype=np.float64),
            "DD": np.asarray(rows["DD"], dtype=bool),
        }

    def add(self, valve: str, row: Mapping[str, Any]) -> None:
        """One record (a row of `bayes_fdi.deployment.serve.records`)."""
        units = self.units[valve]

        def phys(c: str, v: float) -> float:
            return float(to_physical(v, c, units[c]))

        x, f = float(row["VMV_X"]), float(row["VMV_F"])
        point = {
            "t": int(row["time"]) * 1000,
            "X": _clean(phys("X", row["X"])),
            "F": _clean(phys("F", row["F"])),
            "X_vmv": _clean(phys("X", x)),
            "X_vu": _clean(phys("X", x + row["VU_X"]) - phys("X", x)),
            "F_vmv": _clean(phys("F", f)),
            "F_vu": _clean(phys("F", f + row["VU_F"]) - phys("F", f)),
            "status": str(row["status"]),
            "state": str(row["state"]),
            "p": _clean(float(row["probability"])),
            "DD": bool(row["DD"]),
        }
        self.history[valve].append(point)
        self.fresh[valve].append(point)
        self._alarm(valve, point)

    def load(self, valve: str, records: Mapping[str, Any]) -> None:
        """Records from before this process (the log's last hour: columns of record rows, or
        `~bayes_fdi.deployment.serve.durable_log.read_recent`'s dataset; oldest first): put
        before the points added since; the valve's alarms in that window replayed from them."""
        if np.asarray(records["time"]).dtype.kind == "M":  # the log's date-times
            seconds = np.asarray(records["time"]).astype("datetime64[s]").astype(np.int64)
            records = {k: np.asarray(records[k]) for k in _RECORD_COLUMNS} | {"time": seconds}
        cols = self._points(valve, records)
        history = self.history[valve]
        now = history.ordered()
        older = cols["t"] < (now["t"][0] if history.n else np.iinfo(np.int64).max)
        merged = {k: np.concatenate([cols[k][older], now[k]]) for k in cols}
        history.replace(merged)
        if not merged["t"].size:
            return
        first = merged["t"][0]
        self.active.pop(valve, None)
        kept = [a for a in self.alarms if a["valve"] != valve or a["start"] < first]
        self.alarms.clear()
        self.alarms.extend(kept)
        dd = merged["DD"]
        for i in np.flatnonzero(dd | np.concatenate([[False], dd[:-1]])):
            self._alarm(valve, {k: _clean(_scalar(v[i])) for k, v in merged.items()})
        newest_first = sorted(self.alarms, key=lambda a: a["start"], reverse=True)
        self.alarms.clear()
        self.alarms.extend(newest_first)

    def _alarm(self, valve: str, point: Mapping[str, Any]) -> None:
        alarm = self.active.get(valve)
        if point["DD"] and alarm is None:
            alarm = {
                "valve": valve,
                "start": point["t"],
                "end": None,
                "state": "",
                "probability": None,
                "status": point["status"],
                "active": True,
            }
            self.active[valve] = alarm
            self.alarms.appendleft(alarm)
        if alarm is None:
            return
        if not point["DD"]:
            alarm["end"], alarm["active"] = point["t"], False
            del self.active[valve]
            return
        if point["status"] in ("BLURRED", "DAZZLED"):
            alarm["status"] = point["status"]
            if point["state"] not in ("", "fn"):
                alarm["state"], alarm["probability"] = point["state"], point["p"]

    def snapshot(self, valve: str | None = None) -> dict[str, Any]:
        """What the page draws first: the history of the valves it draws (``valve``, or the
        first ``panels``), every valve's last point, the alarms."""
        names = list(self.units)
        drawn = [valve] if valve in self.units else names[: self.panels]
        latest = {}
        for v in names:
            h = self.history[v]
            if h.n:
                i = (h.head - 1) % h.size
                latest[v] = {k: _clean(h.columns[k][i]) for k in ("status", "state")}
                latest[v] |= {"t": int(h.columns["t"][i]), "p": _clean(float(h.columns["p"][i]))}
        return {
            "valves": [
                {"name": v, "X_unit": u["X"], "F_unit": u["F"]} for v, u in self.units.items()
            ],
            "panels": self.panels,
            "keep": self.history[names[0]].size if names else 0,
            "drawn": drawn,
            "history": {v: self.history[v].as_json() for v in drawn},
            "latest": latest,
            "alarms": list(self.alarms),
        }

    def message(self) -> dict[str, Any] | None:
        """The new records since the last message, and the alarms (None: nothing new)."""
        fresh = {v: _columns(p) for v, p in self.fresh.items() if p}
        if not fresh:
            return None
        for v in fresh:
            self.fresh[v] = []
        return {"points": fresh, "alarms": list(self.alarms)}

    async def broadcast(self, period: float = 1.0) -> None:
        """Send a message to every connected page each ``period`` s (until cancelled)."""
        while True:
            await asyncio.sleep(period)
            message = self.message()
            if message is None:
                continue
            text = json.dumps(message, allow_nan=False)
            self.sent += 1
            for queue in list(self.queues):
                if queue.qsize() < 30:  # a page that stopped reading is not fed forever
                    queue.put_nowait(text)

    async def stream(self) -> AsyncIterator[str]:
        """Server-sent events of one page."""
        queue: asyncio.Queue = asyncio.Queue()
        self.queues.add(queue)
        try:
            yield "retry: 2000\n\n"
            while True:
                try:
                    text = await asyncio.wait_for(queue.get(), 15.0)
                except TimeoutError:
                    yield ": keep-alive\n\n"
                    continue
                yield f"data: {text}\n\n"
        finally:
            self.queues.discard(queue)


def _columns(points: list[dict[str, Any]]) -> dict[str, list[Any]]:
    return {k: [p[k] for p in points] for k in _FIELDS}


def live_app(hub: LiveHub) -> Any:
    """The Starlette application of the page."""
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, HTMLResponse, JSONResponse, StreamingResponse
    from starlette.routing import Route

    plotly_path = plotly_js_path()

    async def page(request: Any) -> HTMLResponse:
        return HTMLResponse(_PAGE)

    async def state(request: Any) -> JSONResponse:
        return JSONResponse(hub.snapshot(request.query_params.get("valve")))

    async def events(request: Any) -> StreamingResponse:
        return StreamingResponse(
            hub.stream(), media_type="text/event-stream", headers={"Cache-Control": "no-cache"}
        )

    async def plotly_js(request: Any) -> FileResponse:
        return FileResponse(plotly_path, media_type="text/javascript")

    routes = [
        Route("/", page),
        Route("/api/state", state),
        Route("/events", events),
        Route("/static/plotly.min.js", plotly_js),
    ]
    return Starlette(routes=routes)


async def serve_page(hub: LiveHub, host: str, port: int, stopped: asyncio.Event) -> None:
    """Serve the page with uvicorn until ``stopped`` is set (signals are ``serve``'s)."""
    import uvicorn

    class _Server(uvicorn.Server):
        @contextlib.contextmanager
        def capture_signals(self):  # serve's own handlers stop everything
            yield

    config = uvicorn.Config(
        live_app(hub), host=host, port=port, log_level="warning", lifespan="off", access_log=False
    )
    server = _Server(config)
    task = asyncio.create_task(server.serve())
    await stopped.wait()
    server.should_exit = True
    server.force_exit = True  # open event streams would hold the shutdown
    with contextlib.suppress(asyncio.CancelledError):
        await asyncio.wait_for(task, 5.0)


_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>bayes-fdi serve: live SEVA</title>
<script src="/static/plotly.min.js"></script>
<style>
body{font-family:system-ui,sans-serif;margin:1em;color:#222}
table{border-collapse:collapse;margin:.5em 0}
td,th{border:1px solid #ccc;padding:2px 8px;font-size:90%}
.CLEAR{background:#c8e6c9}.BLURRED{background:#ffe0b2}
.DAZZLED{background:#ffcdd2}.BLIND{background:#cfd8dc}
.panel{border:1px solid #ddd;margin:.5em 0;padding:.3em}.row{display:flex;flex-wrap:wrap}
.chart{width:560px;height:230px}.ribbon{width:1120px;height:90px}
</style></head><body>
<h2>bayes-fdi serve: live SEVA status</h2>
<p>Last update: <span id="updated">waiting for data</span> &middot;
<span id="count">0</span> records received</p>
<h3>Valves</h3><table id="overview"><thead><tr><th>valve</th><th>status</th><th>fault</th>
<th>probability</th><th>time (UTC)</th></tr></thead><tbody></tbody></table>
<h3>Alarms</h3><table id="alarms"><thead><tr><th>valve</th><th>fault</th><th>probability</th>
<th>status</th><th>start (UTC)</th><th>end (UTC)</th></tr></thead><tbody></tbody></table>
<div id="panels"></div>
<script>
const STATUS = ["CLEAR", "BLURRED", "DAZZLED", "BLIND"];
const COLOUR = {CLEAR: "#2e7d32", BLURRED: "#ef6c00", DAZZLED: "#c62828", BLIND: "#607d8b"};
let keep = 3600, hist = {}, drawn = [], latest = {}, count = 0;
const fmt = t => t === null ? "" : new Date(t).toISOString().slice(0, 19).replace("T", " ");
const pct = p => p === null || p === undefined ? "" :
  (100 * p).toFixed(1) + " %";
const date = ts => ts.map(t => new Date(t));
function gapped(h) {  // a null point where seconds are missing: no line across the gap
  const out = {};
  for (const k in h) out[k] = [];
  h.t.forEach((t, i) => {
    if (i > 0 && t - h.t[i - 1] > 1000)
      for (const k in h) out[k].push(k === "t" ? h.t[i - 1] + 1000 : null);
    for (const k in h) out[k].push(h[k][i]);
  });
  return out;
}
function band(x, v, u) {  // VMV +- VU: one closed polygon per stretch without a gap (BLIND)
  const bx = [], by = [];
  let run = [];
  const close = () => {
    if (!run.length) return;
    if (bx.length) { bx.push(null); by.push(null); }
    run.forEach(i => { bx.push(x[i]); by.push(v[i] + u[i]); });
    run.slice().reverse().forEach(i => { bx.push(x[i]); by.push(v[i] - u[i]); });
    run = [];
  };
  x.forEach((_, i) => { if (v[i] === null || u[i] === null) close(); else run.push(i); });
  close();
  return {x: bx, y: by};
}
function chart(h, q) {
  const g = gapped(h), x = date(g.t), b = band(x, g[q + "_vmv"], g[q + "_vu"]);
  return [
    {x: b.x, y: b.y, mode: "lines", line: {width: 0}, fill: "toself",
     fillcolor: "rgba(33,150,243,0.25)", name: "VMV \u00b1 VU", hoverinfo: "skip"},
    {x: x, y: g[q + "_vmv"], mode: "lines", line: {color: "#1565c0", dash: "dot"}, name: "VMV"},
    {x: x, y: g[q], mode: "lines", line: {color: "#222", width: 1}, name: q + " measured"}];
}
function ribbon(h) {
  return STATUS.map(s => {
    const x = [], y = [], text = [];
    h.t.forEach((t, i) => { if (h.status[i] === s) { x.push(new Date(t)); y.push(0);
      text.push(h.state[i] + " " + pct(h.p[i])); } });
    return {x: x, y: y, text: text, mode: "markers", name: s, type: "scattergl",
            marker: {symbol: "square", size: 9, color: COLOUR[s]}};
  });
}
function panel(v) {
  const div = document.createElement("div");
  div.className = "panel"; div.id = "panel-" + v.name;
  div.innerHTML = "<b>" + v.name + "</b><div class='row'><div class='chart' id='X-" + v.name +
    "'></div><div class='chart' id='F-" + v.name + "'></div></div><div class='ribbon' id='S-" +
    v.name + "'></div>";
  document.getElementById("panels").appendChild(div);
}
function layout(title, unit) {
  return {title: {text: title, font: {size: 13}}, margin: {l: 50, r: 10, t: 30, b: 30},
          yaxis: {title: unit}, xaxis: {type: "date"}, legend: {orientation: "h", y: -0.25}};
}
function draw(v) {
  const h = hist[v.name];
  Plotly.react("X-" + v.name, chart(h, "X"), layout("X: stem position", v.X_unit));
  Plotly.react("F-" + v.name, chart(h, "F"), layout("F: flow", v.F_unit));
  Plotly.react("S-" + v.name, ribbon(h), {margin: {l: 50, r: 10, t: 10, b: 30},
    yaxis: {visible: false}, xaxis: {type: "date"}, showlegend: true,
    legend: {orientation: "h", y: 1.3}});
}
function overview() {
  const body = document.querySelector("#overview tbody");
  body.innerHTML = Object.keys(latest).sort().map(v => { const p = latest[v];
    return "<tr><td><a href='/?valve=" + encodeURIComponent(v) + "'>" + v +
      "</a></td><td class='" +
      p.status + "'>" + p.status + "</td><td>" + p.state + "</td><td>" + pct(p.p) + "</td><td>" +
      fmt(p.t) + "</td></tr>"; }).join("");
}
function alarms(list) {
  document.querySelector("#alarms tbody").innerHTML = list.map(a => "<tr class='alarm" +
    (a.active ? " active" : "") + "'><td>" + a.valve + "</td><td class='fault'>" +
    (a.state || "?") +
    "</td><td>" + pct(a.probability) + "</td><td class='" + a.status + "'>" + a.status +
    "</td><td>" + fmt(a.start) + "</td><td>" + (a.active ? "active" : fmt(a.end)) +
    "</td></tr>").join("");
}
function newer(h, after) {  // the points of a message later than what is held
  const keepIt = h.t.map(t => after === undefined || t > after);
  const out = {};
  for (const k in h) out[k] = h[k].filter((_, i) => keepIt[i]);
  return out;
}
function append(v, h) {  // new points of a drawn valve, the last `keep` seconds held
  const held = hist[v];
  for (const k in held) held[k] = held[k].concat(h[k]);
  const first = held.t.findIndex(t => t > held.t[held.t.length - 1] - 1000 * keep);
  if (first > 0) for (const k in held) held[k] = held[k].slice(first);
}
async function start() {
  const queued = [];
  const source = new EventSource("/events");  // opened first: no message is missed
  source.onmessage = e => queued.push(JSON.parse(e.data));
  const want = new URLSearchParams(location.search).get("valve");
  const url = "/api/state" + (want ? "?valve=" + encodeURIComponent(want) : "");
  const state = await (await fetch(url)).json();
  keep = state.keep;
  latest = state.latest;
  drawn = state.valves.filter(v => state.drawn.includes(v.name));
  for (const v of drawn) { hist[v.name] = state.history[v.name]; panel(v); draw(v); }
  count = drawn.reduce((n, v) => n + hist[v.name].t.length, 0);
  overview(); alarms(state.alarms);
  const apply = m => {
    for (const v in m.points) {
      const h = newer(m.points[v], latest[v] && latest[v].t);
      const n = h.t.length;
      if (!n) continue;
      latest[v] = {status: h.status[n - 1], state: h.state[n - 1], p: h.p[n - 1], t: h.t[n - 1]};
      count += n;
      if (hist[v]) append(v, h);
    }
    for (const v of drawn) if (m.points[v.name]) draw(v);
    overview(); alarms(m.alarms);
    const now = new Date().toISOString().slice(11, 19);
    document.getElementById("updated").textContent = now + " UTC";
    document.getElementById("count").textContent = count;
  };
  queued.forEach(apply);
  source.onmessage = e => apply(JSON.parse(e.data));
}
start();
</script></body></html>
"""
