"""A scenario small enough for tests of whole sessions: an 8 x 6 m room mapped in W1, with a
pallet moved, a drum removed and one walker in W2 (seconds, not minutes)."""

import sim


def tiny_room(max_duration=None, beams=271):
    return sim.scenario_from_dict(tiny_room_dict(max_duration, beams))


def write_tiny_room(path, **kw):
    import yaml

    path.write_text(yaml.safe_dump(tiny_room_dict(**kw)))
    return path


def tiny_room_dict(max_duration=None, beams=271):
    w2 = {"name": "W2", "changes": [{"move": "pallet", "to": [4.0, 2.4, 0.0]},
                                    {"remove": "drum"}],
          "people": [{"route": [[0.5, 3.3], [7.5, 3.3]], "speed": 1.0, "loop": False}],
          "route": [[7.0, 1.0], [7.0, 4.0], [1.0, 4.0]]}
    if max_duration is not None:
        w2["max_duration"] = max_duration
    return {
        "name": "tiny_room", "seed": 5, "resolution": 0.05,
        "world": {"bounds": [0.0, 0.0, 8.0, 6.0], "wall_thickness": 0.1,
                  "static": [{"id": "shelf", "center": [4.0, 5.2], "size": [3.0, 0.5]}],
                  "movable": [{"id": "pallet", "center": [2.0, 2.5], "size": [1.2, 0.8]},
                              {"id": "drum", "center": [6.0, 2.0], "radius": 0.3}]},
        "robot": {"start": [1.0, 1.0, 0.0], "radius": 0.3,
                  "lidars": [{"mount": [0.2, 0.0, 0.0], "fov_deg": 270, "beams": beams,
                              "range_max": 10.0, "range_noise_std": 0.01, "rate_hz": 10}]},
        "sessions": [{"name": "W1", "mapping": True,
                      "route": [[7.0, 1.0], [7.0, 4.0], [1.0, 4.0], [1.0, 1.0]]}, w2]}
