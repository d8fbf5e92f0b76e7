"""Validates every message of an MCAP recording against its channel's JSON schema.

Usage: validate_schemas.py FILE. Reads in file order (a file cut short is read up to the cut)
and prints a JSON object of message counts per topic; a message that does not validate, or a
schema that is not a valid JSON schema, is an error (non-zero exit).
"""
import json
import sys

from jsonschema import Draft202012Validator
from jsonschema.validators import validator_for
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader

counts = {}
validators = {}
with open(sys.argv[1], "rb") as f:
    try:
        for schema, channel, message in NonSeekingReader(f, validate_crcs=True).iter_messages(
            log_time_order=False
        ):
            v = validators.get(schema.id)
            if v is None:
                s = json.loads(schema.data)
                cls = validator_for(s, default=Draft202012Validator)
                cls.check_schema(s)
                v = validators[schema.id] = cls(s)
            v.validate(json.loads(message.data))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    except EndOfFile:
        pass
print(json.dumps(counts, sort_keys=True))
