"""One module per `ibrnav` command, each a `register(subparsers)` that adds its flags and a
`run(args)` that parses them, calls the library and prints the result (parsing and printing
only: every algorithm is callable from Python without the command line)."""

__all__ = ["bench", "demo", "drive", "eval_capture", "eval_ibr", "eval_missions", "eval_loc", "eval_track", "explore", "localize", "render",
           "robot_check", "scenic", "scene", "sfm", "vueplan"]
