"""What mjskill's trainers share, as rsl_rl lays it out: the algorithms side by side
(examples/ppo.py: PPO; examples/imitate.py: behaviour cloning from demonstrations) over shared
modules (docs/training.md):

* :mod:`training.args`: argparse value types and the option handling of ``--resume``;
* :mod:`training.rundir`: run directories held by one writer (a lock naming its pid),
  ``log.csv`` appended to and flushed, checkpoints checked when read, SIGINT/SIGTERM as a
  request to stop;
* :mod:`training.export`: policy files (examples/policy_onnx.py's ONNX MLP with its metadata),
  written atomically (training.files);
* :mod:`training.evaluate`: success and return of a policy on fixed seeds in a vector env;
* :mod:`training.files`: files read (regular files only, size-capped, opened without
  blocking) and written (replaced whole through an exclusively created temporary file of a
  short name of the writer's own, keeping the replaced file's mode), the cleanup of those
  temporary files, and fingerprints of the files a run reads;
* :mod:`training.recording`: the MCAP layer of mjskill recordings read with the checks of
  mjskill's own reader (CRCs, structure, cut or damaged), for examples/demos.py;

and the two modules beside them that predate the package: examples/demos.py (demonstrations
read from mjskill recordings and ManiSkill trajectory files) and examples/policy_onnx.py
(the ONNX graph and its edits, also a command line of its own).

The trainers put examples/ on ``sys.path`` (they are run as scripts) and import
``training`` from there.
"""
