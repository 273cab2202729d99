"""The TOML file of ``bayes-fdi serve`` (bayes_fdi.deployment.serve.config): defaults, and a clear
error naming the section and key for every kind of mistake."""

from __future__ import annotations

import pytest

from bayes_fdi.cli import main
from bayes_fdi.deployment.serve.config import ConfigError, load_config, parse_config

_OPEN = '[server]\nsecurity = ["None"]\nallow_anonymous = true\n'


def test_defaults_and_node_pattern():
    cfg = parse_config(_OPEN + "[valves.V101]\n")
    (valve,) = cfg.valves
    assert valve.nodes["CV"] == "ns=2;s=V101.CV" and valve.nodes["F"] == "ns=2;s=V101.F"
    assert valve.units == {"CV": "%", "P1": "kPa", "P2": "kPa", "T1": "degC", "X": "%", "F": "t/h"}
    assert valve.endpoint == cfg.plant.endpoint
    assert cfg.plant.mode == "subscribe" and cfg.plant.speed == 1.0
    assert cfg.http.address == ""  # no page unless asked for
    assert cfg.server.allow_anonymous is True


def test_units_are_normalised_and_a_fault_is_read():
    cfg = parse_config(
        _OPEN + '[valves.A]\nunits = {T1 = "K", P1 = "bar", P2 = "MPa"}\n'
        'fault = {name = "f18", strength = 0.5, onset = 30}\n'
    )
    v = cfg.valves[0]
    assert (v.units["T1"], v.units["P1"], v.units["P2"]) == ("K", "bar", "MPa")
    assert v.fault.name == "f18" and v.fault.strength == 0.5 and v.fault.onset == 30.0


@pytest.mark.parametrize(
    "text, words",
    [
        ("[plant]\nspeed = 1\n", ["no [valves.NAME]"]),
        (_OPEN + "[valves.A]\nnodez = {}\n", ["[valves.A]", "unknown key", "nodez"]),
        (_OPEN + '[valves.A]\nnodes = {Q = "ns=2;s=x"}\n', ["[valves.A] nodes", "unknown channel"]),
        (
            _OPEN + '[valves.A]\nnodes = {CV = "ns=2;q=x"}\n',
            ["nodes", "CV", "not an OPC UA node id"],
        ),
        (_OPEN + '[valves.A]\nunits = {P1 = "psi"}\n', ["[valves.A] units", "psi"]),
        (_OPEN + '[valves.A]\nmodel = "missing.npz"\n', ["model", "does not exist"]),
        (_OPEN + '[valves.A]\nfault = {name = "f99"}\n', ["fault", "f1..f19"]),
        (_OPEN + "[plant]\nspeed = -1\n[valves.A]\n", ["[plant] speed", "> 0"]),
        (_OPEN + '[plant]\nmode = "push"\n[valves.A]\n', ["[plant] mode", "subscribe"]),
        (_OPEN + "[plant]\nperiod = 2\n[valves.A]\n", ["period", "1 Hz"]),
        (_OPEN + '[plant]\nendpoint = "http://x"\n[valves.A]\n', ["endpoint", "opc.tcp"]),
        (_OPEN + '[plant]\nsecurity = "Basic256Sha256_Sign"\n[valves.A]\n', ["certificate"]),
        (_OPEN + '[valves."V 1"]\n', ["valve name"]),
        (_OPEN + '[valves.A]\n[valves.B]\nnodes = {X = "ns=2;s=A.X"}\n', ["also A.X"]),
        ("[valves.A]\n", ["[server] security", "certificate and private_key"]),
        (
            '[server]\nsecurity = ["None"]\n[valves.A]\n',
            ["anonymous access is off", "trusted_clients"],
        ),
        ("[server]\nallow_anonymous = true\n[valves.A]\n", ["[server] security", "certificate"]),
        (_OPEN + "[http]\naddress = 'localhost'\n[valves.A]\n", ["[http] address", "HOST:PORT"]),
        (_OPEN + "[valves.A]\n[extra]\n", ["unknown section", "extra"]),
        ("[valves.A\n", ["not valid TOML"]),
    ],
)
def test_mistakes_are_named(text, words):
    with pytest.raises(ConfigError) as info:
        parse_config(text, source="valve.toml")
    message = str(info.value)
    assert message.startswith("valve.toml")
    for word in words:
        assert word in message, (word, message)


def test_the_simulated_plant_does_not_need_the_server_section(tmp_path):
    path = tmp_path / "valve.toml"
    path.write_text(
        "[valves.A]\n[simulation]\nduration = 10\noutages = [{start = 2, seconds = 3}]\n"
    )
    cfg = load_config(path, publishing=False)
    assert cfg.simulation.outages == ((2, 3),)
    with pytest.raises(ConfigError, match="certificate"):
        load_config(path)


def test_paths_are_relative_to_the_toml(tmp_path):
    (tmp_path / "m.npz").write_bytes(b"")
    path = tmp_path / "valve.toml"
    path.write_text(_OPEN + '[log]\nfolder = "logs"\n[valves.A]\nmodel = "m.npz"\n')
    cfg = load_config(path)
    assert cfg.valves[0].model == str(tmp_path / "m.npz")
    assert cfg.log.folder == str(tmp_path / "logs")


def test_the_command_line_reports_a_config_error_in_one_line(tmp_path, capsys):
    path = tmp_path / "valve.toml"
    path.write_text(_OPEN + '[valves.A]\nunits = {F = "gallons"}\n')
    assert main(["serve", "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("bayes-fdi serve: error:") and "gallons" in err[0]
