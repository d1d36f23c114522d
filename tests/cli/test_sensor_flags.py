"""The sensor flags of ``doefab train`` / ``evaluate``: what cannot work is refused before any output."""

import pytest


@pytest.mark.parametrize("cmd", ["train", "evaluate"])
def test_a_response_for_an_rgb_task_is_refused(cmd, one_clear_error):
    one_clear_error(lambda f, t: [cmd, "--task", "hdr", "--sensor-response", "Nikon D5100", "--out", t / "o"], 2,
                    "--sensor-response forms the hyperspectral task's captures only")


@pytest.mark.parametrize("cmd", ["train", "evaluate"])
def test_a_response_that_misses_the_bands_is_refused_before_any_output(cmd, one_clear_error):
    one_clear_error(lambda f, t: [cmd, "--task", "hyperspectral", "--sensor-response", "Sigma SD Merrill",
                                  "--out", t / "o"], 2, "400–680 nm")


def test_shipped_networks_are_refused_for_another_sensor_at_the_command_line(one_clear_error):
    line = one_clear_error(lambda f, t: ["evaluate", "--task", "hdr", "--read-noise-e", "20", "--out", t / "o"], 2,
                           "trained for another sensor")
    assert "read_noise_e 3 (this camera: 20)" in line and "--sensor-response" not in line


def test_finetune_takes_the_noise_and_refuses_a_response(one_clear_error):
    one_clear_error(lambda f, t: ["finetune", "--design", f / "design", "--sensor-response", "x.csv", "--out",
                                  t / "o"], 2, "unrecognized arguments: --sensor-response")
