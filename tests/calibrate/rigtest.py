"""What the rig tests (test_plate_rig.py, test_shear_rig.py) share: the
assertion and the check that a rig refuses bad scene keys by name."""
import os
import subprocess

NEVER = "/demfem-test-never-created"


def ensure(cond, what):
    if not cond:
        raise AssertionError(what)


def bad_keys_refused(rig, scene, cases):
    """Each (sets, word) of cases: the rig started on scene with those --set
    overrides exits 1 with a message naming word, before it creates its
    shared-memory segment."""
    for bad, word in cases:
        cmd = [rig, "--scene", scene, "--shm", NEVER]
        for b in bad:
            cmd += ["--set", b]
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=60)
        print("  --set %s: exit %d: %s" % (bad, p.returncode, p.stdout.strip()))
        ensure(p.returncode == 1, "--set %s: exit %d, not 1" % (bad, p.returncode))
        ensure(word in p.stdout, "--set %s: the message does not name %s" % (bad, word))
    ensure(not os.path.exists("/dev/shm" + NEVER), "a segment was left behind")
