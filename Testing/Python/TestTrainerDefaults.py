"""The ParaView plugin's defaults are the trainer's: every property of the GaussianFieldTrainer proxy in
Module/ParaView/Plugin/BIGUSFilters.xml whose command is a setter of vtkGaussianFieldTrainer has default_values
equal to what a new filter's getter returns, and those getters read the one bigus::TrainerSettings (its defaults,
bigusTrainer.h). A default changed in TrainerSettings and not in the XML (or the other way) fails here, naming the
property and both values. Likewise each range domain of a one-element property must be the setter's clamp.

Usage: TestTrainerDefaults.py SOURCE_DIR (run with the build's Python package on PYTHONPATH).
"""
import sys
import xml.etree.ElementTree as ET

import bigus


def xml_defaults(path):
    """{property name: (command, [default values as strings])} of the trainer's proxy."""
    tree = ET.parse(path)
    for proxy in tree.iter("SourceProxy"):
        if proxy.get("class") == "vtkGaussianFieldTrainer":
            return {
                p.get("name"): (p.get("command"), (p.get("default_values") or "").split())
                for p in proxy
                if p.tag.endswith("VectorProperty") and p.get("command", "").startswith("Set")
            }
    raise SystemExit(f"{path}: no SourceProxy of class vtkGaussianFieldTrainer")


def xml_ranges(path):
    """{property name: (command, min, max)} of the trainer's one-element properties with a range domain."""
    tree = ET.parse(path)
    for proxy in tree.iter("SourceProxy"):
        if proxy.get("class") == "vtkGaussianFieldTrainer":
            ranges = {}
            for p in proxy:
                domain = next((d for d in p if d.tag in ("DoubleRangeDomain", "IntRangeDomain")), None)
                if domain is not None and p.get("number_of_elements") == "1":
                    ranges[p.get("name")] = (p.get("command"), domain.get("min"), domain.get("max"))
            return ranges
    return {}


def check_ranges(path):
    """Each range domain of the XML is the setter's clamp: a value below its min reads back as the min, one above
    its max as the max (ParaView's panel and a script that sets the filter directly agree); NaN is refused and the
    value kept. Returns the failures."""
    failures = []
    for name, (command, low, high) in sorted(xml_ranges(path).items()):
        getter = "Get" + command[len("Set"):]
        for bound, outside in ((low, lambda b: b - 1 - abs(b)), (high, lambda b: b + 1 + abs(b))):
            if bound is None:
                continue
            trainer = bigus.vtkGaussianFieldTrainer()
            value = float(bound)
            try:
                getattr(trainer, command)(outside(value))
            except TypeError:  # an int setter: the outside value as an int
                try:
                    getattr(trainer, command)(int(outside(value)))
                except OverflowError:  # the setter's type ends at the bound (Seed: unsigned int)
                    continue
            if float(getattr(trainer, getter)()) != value:
                failures.append(f"{name}: the XML's range ends at {bound}, {command}({outside(value)}) reads back "
                                f"{getattr(trainer, getter)()}")
    trainer = bigus.vtkGaussianFieldTrainer()
    trainer.GlobalWarningDisplayOff()
    before = trainer.GetElevationSigma()
    trainer.SetElevationSigma(float("nan"))
    if trainer.GetElevationSigma() != before:
        failures.append(f"ElevationSigma: NaN was taken ({trainer.GetElevationSigma()})")
    return failures


def getter_values(trainer, command):
    getter = "Get" + command[len("Set"):]
    if command == "SetLossWeights":
        weights = [0.0, 0.0, 0.0]
        trainer.GetLossWeights(weights)
        return weights
    value = getattr(trainer, getter)()
    return list(value) if isinstance(value, (tuple, list)) else [value]


def same(expected, actual):
    """Whether one default value of the XML (a string) is the getter's @p actual."""
    if isinstance(actual, str):
        return actual == expected
    if isinstance(actual, bool):
        actual = int(actual)
    return float(expected) == float(actual)


def main():
    source = sys.argv[1]
    defaults = xml_defaults(source + "/Module/ParaView/Plugin/BIGUSFilters.xml")
    trainer = bigus.vtkGaussianFieldTrainer()
    failures, checked = [], 0
    for name, (command, expected) in sorted(defaults.items()):
        actual = getter_values(trainer, command)
        if expected == [] and actual in ([None], [""]):
            checked += 1
            continue
        if len(expected) != len(actual) or not all(same(e, a) for e, a in zip(expected, actual)):
            failures.append(f"{name}: the XML says {' '.join(expected)}, vtkGaussianFieldTrainer {actual}")
        checked += 1
    ranges = xml_ranges(source + "/Module/ParaView/Plugin/BIGUSFilters.xml")
    failures += check_ranges(source + "/Module/ParaView/Plugin/BIGUSFilters.xml")
    checked += len(ranges)
    for line in failures:
        print("FAIL " + line)
    print(f"{checked - len(failures)} passed, {len(failures)} failed")
    # The properties that are settings of the trainer must be many: a parse that found none would pass vacuously.
    if checked < 30:
        print(f"FAIL only {checked} properties found in the XML")
        return 1
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
