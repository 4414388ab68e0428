"""`ibrnav localize`: bad input is one clear line on stderr, no traceback."""

import numpy as np

from ibrnav.cli import main


def test_missing_query_file_is_one_clear_error(tmp_path, capsys):
    rc = main(["localize", "synthetic:office", "--query", str(tmp_path / "nope.jpg"), "--method", "pnp",
               "--save", str(tmp_path / "x.rrd")])
    err = capsys.readouterr().err
    assert rc == 2 and "nope.jpg: image file not found" in err and len(err.strip().splitlines()) == 1


def test_unreadable_query_image_is_one_clear_error(tmp_path, capsys):
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe0 definitely not a jpeg")
    rc = main(["localize", "synthetic:office", "--query", str(bad), "--save", str(tmp_path / "x.rrd")])
    err = capsys.readouterr().err
    assert rc == 2 and "broken.jpg: unreadable or truncated image" in err and len(err.strip().splitlines()) == 1


def test_bad_prior_is_one_clear_error(tmp_path, capsys):
    from PIL import Image

    query = tmp_path / "q.png"
    Image.fromarray(np.zeros((480, 640, 3), np.uint8)).save(query)
    rc = main(["localize", "synthetic:office", "--query", str(query), "--method", "pf",
               "--prior", "1,2,three", "--save", str(tmp_path / "x.rrd")])
    err = capsys.readouterr().err
    assert rc == 2 and "--prior '1,2,three'" in err
