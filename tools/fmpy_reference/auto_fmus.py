"""Two copies of the kit's oscillator FMU for fmi_type = "auto"
(tests/validation/oscillator_auto.toml): one whose CoSimulation element
declares neither canGetAndSetFMUstate nor canSerializeFMUstate, one without a CoSimulation element. The
binaries are the same; only modelDescription.xml differs.

    python tools/fmpy_reference/auto_fmus.py SOURCE.fmu OUT_DIR
"""

import os
import re
import sys
import zipfile


def copy(source, target, edit):
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode("utf-8")
                edited = edit(text)
                if edited == text:
                    raise SystemExit(f"{source}: modelDescription.xml has no element to edit")
                data = edited.encode("utf-8")
            dst.writestr(item, data)


def no_rollback(text):
    def edit(m):
        return re.sub(r'(can(GetAndSet|Serialize)FMUstate=")true"', r'\1false"', m.group(0))

    return re.sub(r"<CoSimulation\b[^>]*>", edit, text)


def model_exchange_only(text):
    return re.sub(r"\s*<CoSimulation\b[^>]*?/>", "", text)


if __name__ == "__main__":
    source, out = sys.argv[1:3]
    os.makedirs(out, exist_ok=True)
    copy(source, os.path.join(out, "oscillator_cs_no_rollback.fmu"), no_rollback)
    copy(source, os.path.join(out, "oscillator_me_only.fmu"), model_exchange_only)
