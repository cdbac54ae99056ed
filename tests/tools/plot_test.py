#!/usr/bin/python3
"""tools/plot/raystack-plot on logs whose curves are known: the PNG has the asked size and
the curves' colours where the curves are (and nowhere for a curve not drawn), the area under
a step curve is exact, and bad logs end with the file and line. Skipped (reported as
[  SKIPPED ]) when matplotlib is not installed; deploy/install-deps.sh installs it."""

import os
import struct
import subprocess
import sys
import tempfile
import unittest
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOOL = os.path.join(ROOT, "tools", "plot", "raystack-plot")
HEADER = ("frame,event,pass,seconds,rays,samples,pixels_covered,min_samples,error_estimate,"
          "rel_error_estimate,rmse,relmse\n")


def read_png_rgb(path):
    """(width, height, rows of (r, g, b)) of an 8-bit RGB or RGBA PNG (what matplotlib
    writes), decoded with zlib only."""
    with open(path, "rb") as f:
        data = f.read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, w = 8, b"", 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and colour in (2, 6), (depth, colour)
            bpp = 3 if colour == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        ftype, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if ftype == 1:
                line[i] = (line[i] + a) & 255
            elif ftype == 2:
                line[i] = (line[i] + b) & 255
            elif ftype == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif ftype == 4:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append([tuple(line[x * bpp:x * bpp + 3]) for x in range(w)])
        prev = line
    return w, h, rows


def write_log(path, points, estimate=None):
    with open(path, "w") as f:
        f.write(HEADER)
        for i, (t, rmse) in enumerate(points):
            e = "" if estimate is None else repr(estimate[i])
            f.write(f"0,tick,{i},{t},{1000 * (i + 1)},{100 * (i + 1)},100,{i},{e},,{rmse},\n")


def has_matplotlib():
    try:
        import matplotlib  # noqa: F401
        return True
    except ImportError:
        return False


class PlotTool(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.tmp = self.dir.name

    def tearDown(self):
        self.dir.cleanup()

    def run_tool(self, *args):
        return subprocess.run([sys.executable, TOOL, *args], capture_output=True, text=True)

    def log_of(self, name, *rows):
        """A log `name` in the test's folder holding `rows` (CSV lines) after the header."""
        path = os.path.join(self.tmp, name)
        with open(path, "w") as f:
            f.write(HEADER + "".join(row + "\n" for row in rows))
        return path

    def area_of(self, logs, *args):
        """The tool's run with --area on `logs` (one or a list; then `args`), which must succeed."""
        logs = [logs] if isinstance(logs, str) else logs
        r = self.run_tool(*logs, "-o", os.path.join(self.tmp, "p.png"), "--area", *args)
        self.assertEqual(r.returncode, 0, r.stderr)
        return r

    def test_png_size_and_curve_colours(self):
        a = os.path.join(self.tmp, "a.csv")
        b = os.path.join(self.tmp, "b.csv")
        # a: high error (upper part of the plot); b: low error (lower part).
        write_log(a, [(0.1, 1.0), (1.0, 0.9), (10.0, 0.8)])
        write_log(b, [(0.1, 0.011), (1.0, 0.010), (10.0, 0.009)])
        out = os.path.join(self.tmp, "p.png")
        r = self.run_tool(f"slow={a}", f"fast={b}", "-o", out, "--width", "640",
                          "--height", "400")
        self.assertEqual(r.returncode, 0, r.stderr)
        w, h, rows = read_png_rgb(out)
        self.assertEqual((w, h), (640, 400))

        # matplotlib's C0 (blue, 1f77b4) and C1 (orange, ff7f0e).
        def near(p, q):
            return all(abs(x - y) <= 40 for x, y in zip(p, q))

        def rows_with(colour):
            return [y for y in range(h) if any(near(p, colour) for p in rows[y])]

        blue, orange = rows_with((0x1f, 0x77, 0xb4)), rows_with((0xff, 0x7f, 0x0e))
        self.assertTrue(blue and orange)
        # The slow curve lies above the fast one (smaller y is higher), legend aside: compare
        # the medians of the rows holding each colour.
        self.assertLess(sorted(blue)[len(blue) // 2], sorted(orange)[len(orange) // 2])

    def test_a_standard_output_that_cannot_be_written_is_said_in_a_line(self):
        # Found by a pipeline review: --area to /dev/full ended in a Python traceback.
        a = os.path.join(self.tmp, "a.csv")
        write_log(a, [(0.0, 2.0), (1.0, 1.0), (3.0, 0.5)])
        with open("/dev/full", "w") as full:
            r = subprocess.run([sys.executable, TOOL, a, "-o", os.path.join(self.tmp, "p.png"),
                                "--area"], stdout=full, stderr=subprocess.PIPE, text=True)
        self.assertEqual(r.returncode, 1, r.stderr)
        self.assertIn("raystack-plot: cannot write to the standard output: No space left on device",
                      r.stderr)
        self.assertNotIn("Traceback", r.stderr)

    def test_area_under_a_step_curve(self):
        a = os.path.join(self.tmp, "a.csv")
        write_log(a, [(0.0, 2.0), (1.0, 1.0), (3.0, 0.5)])
        r = self.run_tool(a, "-o", os.path.join(self.tmp, "p.png"), "--area")
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("a: area 4 ", r.stdout)  # 2 x 1 s + 1 x 2 s, up to the end at 3 s
        r = self.run_tool(a, "-o", os.path.join(self.tmp, "p.png"), "--area", "--until", "2")
        self.assertIn("a: area 3 ", r.stdout)

    def test_estimate_curve_and_linear_axes(self):
        a = os.path.join(self.tmp, "a.csv")
        write_log(a, [(0.1, 1.0), (1.0, 0.5)], estimate=[1.1, 0.45])
        out = os.path.join(self.tmp, "p.png")
        r = self.run_tool(a, "-o", out, "--estimate", "--linear", "--title", "t")
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertGreater(os.path.getsize(out), 1000)

    def test_bad_options_are_refused_before_reading(self):
        # Found by a helper reading the docs: a negative --until gave "area 0", and -o p.jpg
        # wrote PNG bytes under a JPEG's name.
        a = os.path.join(self.tmp, "a.csv")
        write_log(a, [(0.0, 2.0), (1.0, 1.0)])
        for args, says in ((("--area", "--until", "-1"), "--until must be"),
                           (("--frame", "-2"), "--frame must be"),
                           (("-o", os.path.join(self.tmp, "p.jpg")), "give a name ending in .png")):
            r = self.run_tool(a, "-o", os.path.join(self.tmp, "p.png"), *args)
            self.assertEqual(r.returncode, 2, args)
            self.assertIn(says, r.stderr)
        self.assertFalse(os.path.exists(os.path.join(self.tmp, "p.jpg")))

    def test_a_curve_holds_each_value_until_the_next_row(self):
        # Found by a researcher: rows were joined by lines, so a curve fell through times where
        # the log holds no row (two renders seemed to cross where neither had a value). A log
        # high until 10 s, then low: across the plot's width the curve stays at its top.
        a = os.path.join(self.tmp, "a.csv")
        write_log(a, [(0.1, 1.0), (1.0, 1.0), (10.0, 0.01)])
        out = os.path.join(self.tmp, "p.png")
        r = self.run_tool(a, "-o", out, "--width", "640", "--height", "400")
        self.assertEqual(r.returncode, 0, r.stderr)
        w, h, rows = read_png_rgb(out)

        def blue(p):
            return all(abs(x - y) <= 40 for x, y in zip(p, (0x1f, 0x77, 0xb4)))

        cells = [(x, y) for y in range(h) for x in range(w) if blue(rows[y][x])]
        top = min(y for _, y in cells)
        # Between 1 s and 10 s (the middle of the curve's columns, past the legend's short
        # line), every blue pixel is on the top line: a line from (1, 1.0) to (10, 0.01) would
        # have blue halfway down.
        xs = sorted({x for x, _ in cells})
        middle = xs[len(xs) * 3 // 4]
        column = [y for x, y in cells if x == middle]
        self.assertTrue(column)
        self.assertLessEqual(max(column) - top, 4, (middle, column, top))

    def test_paths_with_equals_signs(self):
        # Found by a researcher: "feed=0.1.csv" was read as the label "feed" and the file
        # "0.1.csv". A path that names a file is taken whole; a label before it still works.
        os.makedirs(os.path.join(self.tmp, "run=3"))
        for name in ("feed=0.1.csv", os.path.join("run=3", "log.csv")):
            path = os.path.join(self.tmp, name)
            write_log(path, [(0.1, 1.0), (1.0, 0.5)])
            for spec in (path, "mine=" + path, "P=0.1=" + path):
                r = self.run_tool(spec, "-o", os.path.join(self.tmp, "p.png"), "--area")
                self.assertEqual(r.returncode, 0, (spec, r.stderr))
            self.assertIn("P=0.1: area", r.stdout)
        r = self.run_tool("x=" + os.path.join(self.tmp, "none.csv"), "-o", os.path.join(self.tmp, "p.png"))
        self.assertEqual(r.returncode, 1)
        self.assertIn("none.csv: cannot read", r.stderr)

    def test_a_file_that_is_not_text_is_refused(self):
        # Found by a researcher: an EXR given by mistake ended in a Python traceback.
        exr = os.path.join(self.tmp, "image.exr")
        with open(exr, "wb") as f:
            f.write(b"\x76\x2f\x31\x01\x02\x00\x00\x00" + bytes(range(128, 256)) * 4)
        r = self.run_tool(exr, "-o", os.path.join(self.tmp, "p.png"))
        self.assertEqual(r.returncode, 1)
        self.assertIn("image.exr: not a raystack convergence log", r.stderr)
        self.assertNotIn("Traceback", r.stderr)

    def test_bad_logs_name_the_file_and_line(self):
        bad = os.path.join(self.tmp, "bad.csv")
        with open(bad, "w") as f:
            f.write(HEADER + "0,tick,0,0.5,10,10,10,1,,,0.5,\n0,tick,1,zero,1,1,1,1,,,1,\n")
        r = self.run_tool(bad, "-o", os.path.join(self.tmp, "p.png"))
        self.assertEqual(r.returncode, 1)
        self.assertIn("bad.csv:3: seconds is 'zero'", r.stderr)
        r = self.run_tool(os.path.join(self.tmp, "missing.csv"), "-o", "p.png")
        self.assertEqual(r.returncode, 1)
        self.assertIn("missing.csv: cannot read", r.stderr)
        other = os.path.join(self.tmp, "other.csv")
        with open(other, "w") as f:
            f.write("a,b\n1,2\n")
        r = self.run_tool(other, "-o", os.path.join(self.tmp, "p.png"))
        self.assertIn("other.csv:1: not a raystack convergence log", r.stderr)
        noref = os.path.join(self.tmp, "noref.csv")
        write_log(noref, [(0.1, ""), (1.0, "")], estimate=[0.3, 0.2])
        r = self.run_tool(noref, "-o", os.path.join(self.tmp, "p.png"), "--metric", "rmse")
        self.assertEqual(r.returncode, 1)
        self.assertIn("without --reference", r.stderr)
        self.assertFalse(os.path.exists(os.path.join(self.tmp, "p.png")))

    def test_defaults_follow_the_log(self):
        # Found by a new user: a log of `--frames 1` gave "no rows for frame 0", then (with
        # --frame 1) "no rmse values": a render without --reference has the estimate only.
        log = self.log_of("one.csv", "1,tick,0,0.5,10,10,10,2,0.3,,,", "1,tick,1,1.5,20,20,10,4,0.2,,,")
        r = self.area_of(log)
        self.assertIn("no rmse (rendered without --reference): plotting error_estimate", r.stderr)
        self.assertIn("one: area 0.3 (error_estimate x seconds, 0.500 to 1.500 s)", r.stdout)
        self.assertTrue(os.path.exists(os.path.join(self.tmp, "p.png")))
        # A log of several frames: its first, said.
        two = self.log_of("two.csv", "2,tick,0,0.5,10,10,10,1,,,0.5,", "3,tick,0,0.5,10,10,10,1,,,0.9,",
                          "2,tick,1,1.5,10,10,10,1,,,0.25,")
        r = self.area_of(two)
        self.assertIn("two.csv holds frames 2 to 3: plotting frame 2", r.stderr)
        self.assertIn("two: area 0.5 (rmse", r.stdout)
        r = self.run_tool(two, "-o", os.path.join(self.tmp, "p.png"), "--frame", "0")
        self.assertEqual(r.returncode, 1)
        self.assertIn("no rows for frame 0 (it holds frames 2 to 3)", r.stderr)

    def test_nonsense_in_a_log_is_refused_naming_the_line(self):
        # Found by a hostile-input review: an inf rmse gave "area inf", time going back a
        # negative area, a header alone "no rows for frame None", an empty frame a traceback.
        cases = [("0,tick,0,0.5,10,10,10,1,,,inf,\n", "t.csv:2: rmse is inf, not a finite value >= 0"),
                 ("0,tick,0,0.5,10,10,10,1,,,-1,\n", "t.csv:2: rmse is -1, not a finite value >= 0"),
                 ("0,tick,0,1.0,10,10,10,1,,,1,\n0,tick,1,0.5,10,10,10,1,,,1,\n",
                  "t.csv:3: seconds 0.5 is before the row above's"),
                 (",tick,0,0.5,10,10,10,1,,,1,\n", "t.csv:2: frame is '', not a frame number"),
                 ("", "t.csv: no rows (an empty log)")]
        for body, said in cases:
            log = self.log_of("t.csv", *body.splitlines())
            r = self.run_tool(log, "-o", os.path.join(self.tmp, "p.png"))
            self.assertEqual(r.returncode, 1, body)
            self.assertIn(said, r.stderr)
            self.assertNotIn("Traceback", r.stderr)

    def test_logs_of_different_frames_are_named_so(self):
        a = self.log_of("a.csv", "0,tick,0,0.5,10,10,10,1,,,0.5,")
        b = self.log_of("b.csv", "2,tick,0,0.5,10,10,10,1,,,0.5,")
        r = self.area_of([a, b])
        self.assertIn("the logs' first frames differ (0, 2)", r.stderr)
        self.assertIn("b (frame 2): area", r.stdout)

    def test_an_estimate_from_tiles_that_finish_one_by_one_keeps_its_rows(self):
        # --pass-spp = spp: every pixel has 2 samples only at the end; the curve is not one point.
        log = self.log_of("w.csv", "0,tick,0,0.5,10,10,10,0,0.3,,,", "0,tick,0,1.0,10,10,10,0,0.2,,,",
                          "0,pass,1,2.0,10,10,10,4,0.1,,,")
        r = self.area_of(log, "--metric", "error_estimate")
        self.assertIn("w: area 0.35 (error_estimate x seconds, 0.500 to 2.000 s)", r.stdout)

    def test_an_estimate_starts_once_every_pixel_has_two_samples(self):
        # Before, it averages the few pixels that have two: a curve from far below (a user's plot).
        log = self.log_of("e.csv", "0,tick,0,0.5,10,10,10,1,0.01,,,", "0,tick,1,1.0,10,10,10,2,0.4,,,",
                          "0,tick,2,2.0,10,10,10,4,0.2,,,")
        r = self.area_of(log, "--metric", "error_estimate")
        self.assertIn("e: area 0.4 (error_estimate x seconds, 1.000 to 2.000 s)", r.stdout)


if __name__ == "__main__":
    if not has_matplotlib():
        print("[  SKIPPED ] python3-matplotlib is not installed (deploy/install-deps.sh)")
        sys.exit(0)
    unittest.main(verbosity=2)
