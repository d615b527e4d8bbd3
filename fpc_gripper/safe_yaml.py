"""Hardened YAML for every config file the package reads: limits, strict scalars, clear errors."""

import dataclasses
import math
import os
import pathlib
import re
import reprlib

__all__ = ['ConfigError', 'YamlLimits', 'DEFAULT_YAML_LIMITS', 'Where', 'brief', 'load_yaml',
           'parse_yaml']


class ConfigError(ValueError):
    """
    A config file that cannot be used, as one line: ``<file>: <key path>: <why>``.

    Attributes
    ----------
    source : str
        The file (or what stands for it).
    path : str
        Key path inside it, e.g. ``fingers[1].design.Lx`` ('' for the whole document).
    reason : str
        What is wrong, with the value and its unit.

    """

    def __init__(self, source, path, reason):
        self.source, self.path, self.reason = str(source), str(path), str(reason)
        super().__init__(': '.join(part for part in (self.source, self.path, self.reason)
                                   if part))


@dataclasses.dataclass(frozen=True)
class YamlLimits:
    """
    What a config file may hold before it is refused unread.

    Attributes
    ----------
    max_bytes : int
        File size [byte]. PyYAML parses about 70 kB/s of the worst text (every character
        a token), so this also bounds the time a hostile file takes to about 2 s.
    max_depth : int
        Nesting of collections, aliases expanded.
    max_aliases : int
        Alias references (``*name``) in the document.
    max_nodes : int
        Nodes of the document, as written and with every alias expanded (what a consumer
        walking the data would visit): the second stops an alias bomb ("billion laughs").
    max_number_chars : int
        Characters of one number (no number a config needs is longer).

    """

    max_bytes: int = 128 << 10
    max_depth: int = 32
    max_aliases: int = 64
    max_nodes: int = 20_000
    max_number_chars: int = 40


#: The limits every loader of the package uses.
DEFAULT_YAML_LIMITS = YamlLimits()

_TAG = 'tag:yaml.org,2002:'
_ALLOWED_TAGS = {_TAG + name for name in ('str', 'int', 'float', 'bool', 'null', 'seq', 'map',
                                          'merge')}
# YAML 1.2 core schema, decimal only: no 0x/0o/0b, no underscores, no sexagesimal, no leading
# zero on an integer (YAML 1.1 reads 010 as 8).
_INT = re.compile(r'[-+]?(?:0|[1-9][0-9]*)\Z')
_FLOAT = re.compile(r'[-+]?(?:\.[0-9]+|(?:0|[1-9][0-9]*)(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?\Z'
                    r'|[-+]?\.(?:inf|Inf|INF)\Z|\.(?:nan|NaN|NAN)\Z')
_BOOL = re.compile(r'(?:true|True|TRUE|false|False|FALSE)\Z')
_NULL = re.compile(r'(?:~|null|Null|NULL|)\Z')
# What YAML 1.1 reads as a number although it is not a plain decimal (hex, octal, binary,
# underscores, sexagesimal, leading zeros), and YAML 1.2's 0o octal: refused, not guessed.
_NUMBER_LIKE = re.compile(
    r'[-+]?(?:0b[0-1_]+|0o?[0-7_]+|0x[0-9a-fA-F_]+|[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?'
    r'|[0-9][0-9_]*(?:\.[0-9_]*)?(?:[eE][-+]?[0-9]+)?|\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?)\Z')
_IDENTIFIER = re.compile(r'[A-Za-z_][A-Za-z0-9_]*\Z')
_BRIEF_CHARS = 100
_BRIEF = reprlib.Repr()
_BRIEF.maxlevel, _BRIEF.maxstring, _BRIEF.maxother = 2, 40, 40
_BRIEF.maxlist = _BRIEF.maxtuple = _BRIEF.maxdict = _BRIEF.maxset = 4


def brief(value):
    """
    Return a short repr of any value for an error message: bounded in time and length.

    A value built from aliases may be a huge shared structure; ``repr`` of it would take
    minutes and gigabytes, so every message about a value goes through here.
    """
    if isinstance(value, float):
        return repr(value)
    text = _BRIEF.repr(value)
    return text if len(text) <= _BRIEF_CHARS else f'{text[:60]}...{text[-30:]}'


_TYPE_NAMES = {type(None): 'null', bool: 'boolean', str: 'string', list: 'list',
               dict: 'mapping', int: 'integer', float: 'number'}


def _type_name(value):
    return _TYPE_NAMES.get(type(value), type(value).__name__)


class Where:
    """
    A place in a config file (the file and a key path), and checks that name it.

    ``Where('g.yaml') / 'fingers' / 1 / 'design'`` is ``g.yaml: fingers[1].design``.
    Every check returns the value converted, or raises `ConfigError` naming the place.
    """

    __slots__ = ('source', 'path')

    def __init__(self, source, path=''):
        self.source, self.path = str(source), str(path)

    def __truediv__(self, key):
        if isinstance(key, int) and not isinstance(key, bool):
            part = f'[{key}]'
        elif isinstance(key, str) and _IDENTIFIER.match(key):
            part = f'.{key}' if self.path else key
        else:
            part = f'[{brief(key)}]'
        return Where(self.source, self.path + part)

    def sub(self, subpath):
        """Return the place `subpath` (already written as a path, e.g. 'emc.E1') below this."""
        joint = '.' if self.path and subpath and subpath[0] != '[' else ''
        return Where(self.source, self.path + joint + subpath)

    def __str__(self):
        return ': '.join(part for part in (self.source, self.path) if part)

    def error(self, reason):
        """Return the `ConfigError` of this place."""
        return ConfigError(self.source, self.path, reason)

    def mapping(self, value, allowed=None, what='a mapping'):
        """Return `value` as a dict; with `allowed`, unknown keys are refused by name."""
        if not isinstance(value, dict):
            raise self.error(f'expected {what}, got {_type_name(value)} {brief(value)}')
        if allowed is not None:
            unknown = sorted(brief(k) for k in value if k not in allowed)
            if unknown:
                more = f' and {len(unknown) - 5} more' if len(unknown) > 5 else ''
                raise self.error(f'unknown key(s) {", ".join(unknown[:5])}{more}; allowed: '
                                 f'{", ".join(sorted(allowed))}')
        return value

    def sequence(self, value, min_items=0, max_items=None, what='items'):
        """Return `value` as a list of `min_items` to `max_items` entries."""
        if not isinstance(value, list):
            raise self.error(f'must be a list of {what}, got {_type_name(value)} '
                             f'{brief(value)}')
        if len(value) < min_items or (max_items is not None and len(value) > max_items):
            span = (f'{min_items}' if min_items == max_items else
                    f'{min_items} to {max_items}' if max_items is not None else
                    f'at least {min_items}')
            raise self.error(f'must hold {span} {what}, got {len(value)}')
        return value

    def number(self, value, unit, low=None, high=None, low_open=False, high_open=False):
        """
        Return `value` as a finite float in [low, high] (open ends with `*_open`).

        The message states the bound and the unit, e.g. 'must be > 0 [m], got -0.11'.
        """
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(f'must be a number {unit}, got {_type_name(value)} '
                             f'{brief(value)}')
        try:
            number = float(value)
        except OverflowError:
            number = math.copysign(math.inf, value)
        if not math.isfinite(number):
            raise self.error(f'must be a finite number {unit}, got {number}')
        below = low is not None and (number <= low if low_open else number < low)
        above = high is not None and (number >= high if high_open else number > high)
        if below or above:
            raise self.error(f'must be {_interval(low, high, low_open, high_open)} {unit}, '
                             f'got {number!r}')
        return number

    def integer(self, value, low, high, unit=''):
        """Return `value` as an int in [low, high]."""
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            got = value if isinstance(value, int) and not isinstance(value, bool) else \
                f'{_type_name(value)} {brief(value)}'
            raise self.error(f'must be an integer in [{low}, {high}]'
                             f'{" " + unit if unit else ""}, got {got}')
        return int(value)

    def boolean(self, value):
        """Return `value` if it is true or false."""
        if not isinstance(value, bool):
            raise self.error(f'must be true or false, got {_type_name(value)} {brief(value)}')
        return value

    def string(self, value, max_chars, pattern=None, what='a string'):
        """Return `value` as a non-empty str of at most `max_chars`, matching `pattern`."""
        if not isinstance(value, str) or not value:
            raise self.error(f'must be {what}, got {_type_name(value)} {brief(value)}')
        if len(value) > max_chars:
            raise self.error(f'must be at most {max_chars} characters, got {len(value)}: '
                             f'{brief(value)}')
        if pattern is not None and not pattern.match(value):
            raise self.error(f'must be {what}, got {brief(value)}')
        return value

    def choice(self, value, choices):
        """Return `value` if it is one of `choices`."""
        if not isinstance(value, str) or value not in choices:
            raise self.error(f'must be one of {", ".join(choices)}, got {brief(value)}')
        return value


def _interval(low, high, low_open, high_open):
    if high is None:
        return f'{">" if low_open else ">="} {low:g}'
    if low is None:
        return f'{"<" if high_open else "<="} {high:g}'
    return f'in {"(" if low_open else "["}{low:g}, {high:g}{")" if high_open else "]"}'


class _Refused(Exception):
    """A limit broken while composing; turned into a ConfigError with the file name."""

    def __init__(self, mark, reason):
        super().__init__(reason)
        self.mark, self.reason = mark, reason


def _loader_class(limits):
    """Return a SafeLoader subclass with strict scalars that counts depth and aliases."""
    import yaml

    class Loader(yaml.SafeLoader):
        yaml_implicit_resolvers = {}

        def __init__(self, stream):
            super().__init__(stream)
            self._depth = 0
            self._aliases = 0
            self._nodes = 0

        def fetch_flow_collection_start(self, token_class):
            # The scanner's simple-key bookkeeping is quadratic in flow nesting: stop it
            # before it starts, not when the composer sees the result.
            if self.flow_level >= limits.max_depth:
                raise _Refused(self.get_mark(), f'nested deeper than {limits.max_depth} levels')
            super().fetch_flow_collection_start(token_class)

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                self._aliases += 1
                if self._aliases > limits.max_aliases:
                    raise _Refused(self.peek_event().start_mark,
                                   f'more than {limits.max_aliases} aliases')
            self._depth += 1
            self._nodes += 1
            try:
                if self._nodes > limits.max_nodes:
                    raise _Refused(self.peek_event().start_mark,
                                   f'more than {limits.max_nodes} values')
                if self._depth > limits.max_depth:
                    raise _Refused(self.peek_event().start_mark,
                                   f'nested deeper than {limits.max_depth} levels')
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

    first = list('-+0123456789.')
    Loader.add_implicit_resolver(_TAG + 'bool', _BOOL, list('tTfF'))
    Loader.add_implicit_resolver(_TAG + 'int', _INT, first)
    Loader.add_implicit_resolver(_TAG + 'float', _FLOAT, first)
    Loader.add_implicit_resolver(_TAG + 'null', _NULL, ['~', 'n', 'N', ''])
    Loader.add_implicit_resolver(_TAG + 'merge', re.compile(r'<<\Z'), ['<'])
    return Loader


def _line(mark):
    return '' if mark is None else f'line {mark.line + 1}, column {mark.column + 1}: '


class _TreeCheck:
    """
    Walk the composed document once, aliases expanded but each shared node checked once.

    Refuses recursive aliases, nesting and expanded size beyond the limits, keys that are
    not strings, duplicate keys, tags other than the plain data types and numbers that are
    not plain decimals, each naming the key path.
    """

    def __init__(self, source, limits):
        self.source, self.limits = source, limits
        self.done = {}          # id(node) -> (expanded size, height)
        self.active = set()
        self.total = 0

    def fail(self, where, node, reason):
        raise ConfigError(self.source, where.path, _line(node.start_mark) + reason)

    def visit(self, node, where, depth):
        key = id(node)
        if key in self.active:
            self.fail(where, node, 'recursive alias: the value contains itself')
        if key in self.done:
            size, height = self.done[key]
        else:
            self.active.add(key)
            size, height = self._check(node, where, depth)
            self.active.discard(key)
            self.done[key] = (size, height)
        if depth + height > self.limits.max_depth:
            self.fail(where, node, f'nested deeper than {self.limits.max_depth} levels '
                      '(aliases expanded)')
        self.total += size
        if self.total > self.limits.max_nodes:
            self.fail(where, node, f'expands to more than {self.limits.max_nodes} values '
                      '(aliases expanded): an alias bomb?')
        return size, height

    def _check(self, node, where, depth):
        import yaml
        if node.tag not in _ALLOWED_TAGS:
            self.fail(where, node, f'tag {brief(node.tag)} is not accepted (plain strings, '
                      'numbers, booleans, null, lists and mappings only)')
        if isinstance(node, yaml.ScalarNode):
            self._scalar(node, where)
            return 1, 0
        before = self.total
        height = 0
        if isinstance(node, yaml.SequenceNode):
            children = [(where / i, child) for i, child in enumerate(node.value)]
        else:
            children = self._mapping(node, where)
        for place, child in children:
            height = max(height, 1 + self.visit(child, place, depth + 1)[1])
        size = 1 + self.total - before
        self.total = before
        return size, height

    def _mapping(self, node, where):
        import yaml
        children, seen = [], {}
        for key, value in node.value:
            if key.tag == _TAG + 'merge':
                children.append((where, value))
                continue
            if not isinstance(key, yaml.ScalarNode):
                self.fail(where, key, f'keys must be strings, got a {key.id}')
            if key.tag != _TAG + 'str':
                self.fail(where, key, f'keys must be strings, got {key.tag.rsplit(":", 1)[-1]} '
                          f'{brief(key.value)}')
            if key.value in seen:
                self.fail(where / key.value, key, f'duplicate key {brief(key.value)} (first '
                          f'on line {seen[key.value] + 1})')
            seen[key.value] = key.start_mark.line
            children.append((where / key.value, value))
        return children

    def _scalar(self, node, where):
        value, tag = node.value, node.tag
        if tag in (_TAG + 'int', _TAG + 'float'):
            pattern = _INT if tag == _TAG + 'int' else _FLOAT
            if len(value) > self.limits.max_number_chars or not pattern.match(value):
                self.fail(where, node, f'{brief(value)} is not a plain decimal number')
        elif tag == _TAG + 'bool' and not _BOOL.match(value):
            self.fail(where, node, f'{brief(value)} is not true or false')
        elif tag == _TAG + 'str' and node.style is None and _NUMBER_LIKE.match(value):
            self.fail(where, node, f'{brief(value)} looks like a number but is not a plain '
                      'decimal one (hex, octal, binary, underscores, sexagesimal and leading '
                      'zeros are refused); quote it if it is text')


def parse_yaml(text, source='<string>', limits=DEFAULT_YAML_LIMITS):
    """
    Parse one YAML document under `limits`; see `load_yaml`.

    Parameters
    ----------
    text : str
        The document.
    source : str
        Name of the file, for messages.
    limits : YamlLimits

    Returns
    -------
    object
        Plain data: dict (str keys), list, str, int, float, bool or None.

    Raises
    ------
    ConfigError

    """
    import yaml
    loader = None
    try:
        try:
            loader = _loader_class(limits)(text)
            node = loader.get_single_node()
        except _Refused as exc:
            raise ConfigError(source, '', _line(exc.mark) + exc.reason) from None
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            what = ' '.join('; '.join(str(p) for p in (exc.context, exc.problem) if p).split())
            raise ConfigError(source, '', f'{_line(mark)}malformed YAML: {what[:200]}') from None
        except yaml.reader.ReaderError as exc:
            raise ConfigError(source, '', f'character #x{exc.character:04x} at offset '
                                          f'{exc.position} is not allowed in YAML') from None
        except yaml.YAMLError as exc:
            detail = ' '.join(str(exc).split())
            raise ConfigError(source, '', f'malformed YAML: {detail[:200]}') from None
        if node is None:
            return None
        _TreeCheck(source, limits).visit(node, Where(source), 0)
        try:
            return loader.construct_document(node)
        except yaml.MarkedYAMLError as exc:
            raise ConfigError(source, '', f'{_line(exc.problem_mark)}malformed YAML: '
                                          f'{exc.problem}') from None
    finally:
        if loader is not None:
            loader.dispose()


def load_yaml(path, limits=DEFAULT_YAML_LIMITS, what='config'):
    """
    Read a YAML config file with every limit of `limits` checked before it is parsed.

    Beyond `yaml.safe_load`: the file must be a regular file of at most `max_bytes`, in
    UTF-8, with one document; nesting, aliases and the alias-expanded size are bounded;
    duplicate keys, non-string keys and tags other than the plain data types are refused;
    numbers are YAML 1.2 decimals (``1e6`` is a float; ``0x6E``, ``0o17``, ``1_000``,
    ``1:30`` and ``010`` are refused, not read as 110, 15, 1000, 90 or 8); booleans are
    ``true``/``false`` only (``yes``, ``no``, ``on``, ``off`` stay strings).

    Parameters
    ----------
    path : str or path-like
    limits : YamlLimits
    what : str
        What the file is, for the message when it cannot be read ('gripper config').

    Returns
    -------
    object
        The document as plain data (None for an empty one).

    Raises
    ------
    ConfigError
        A ValueError whose one-line message names the file, the key path and the problem.

    """
    source = os.fspath(path)
    path = pathlib.Path(source)
    try:
        if not path.is_file():
            reason = 'does not exist' if not path.exists() else 'is not a regular file'
            raise ConfigError(source, '', f'cannot read {what}: {reason}')
        with path.open('rb') as stream:
            data = stream.read(limits.max_bytes + 1)
    except OSError as exc:
        raise ConfigError(source, '', f'cannot read {what}: {exc.strerror or exc}') from None
    if len(data) > limits.max_bytes:
        raise ConfigError(source, '', f'{what} is larger than {limits.max_bytes} bytes')
    try:
        text = data.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        raise ConfigError(source, '', f'not UTF-8 text: byte 0x{data[exc.start]:02x} at '
                                      f'offset {exc.start}') from None
    return parse_yaml(text, source, limits)
