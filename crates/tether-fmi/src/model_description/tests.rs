use super::*;

const FULL: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="demo" guid="{1234}"
  description="A demo" author="me" version="1.2" copyright="c" license="MIT"
  generationTool="hand" generationDateAndTime="2024-01-01T00:00:00Z"
  variableNamingConvention="structured" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="demo" canHandleVariableCommunicationStepSize="true"
    canInterpolateInputs="true" maxOutputDerivativeOrder="2" canGetAndSetFMUstate="true"
    canSerializeFMUstate="1" providesDirectionalDerivative="false"/>
  <UnitDefinitions>
    <Unit name="N"><BaseUnit kg="1" m="1" s="-2"/></Unit>
    <Unit name="degC"><BaseUnit K="1" offset="273.15"/><DisplayUnit name="degF" factor="1.8" offset="32"/></Unit>
  </UnitDefinitions>
  <TypeDefinitions>
    <SimpleType name="Force"><Real quantity="Force" unit="N" nominal="10"/></SimpleType>
    <SimpleType name="Mode"><Enumeration><Item name="off" value="0"/><Item name="on" value="1" description="running"/></Enumeration></SimpleType>
    <SimpleType name="Count"><Integer min="0"/></SimpleType>
  </TypeDefinitions>
  <LogCategories><Category name="logAll" description="everything"/></LogCategories>
  <DefaultExperiment startTime="0" stopTime="1" tolerance="1e-6" stepSize="0.001"/>
  <ModelVariables>
    <ScalarVariable name="time" valueReference="0" causality="independent"><Real/></ScalarVariable>
    <ScalarVariable name="x" valueReference="1" causality="output" initial="exact"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="der(x)" valueReference="2"><Real derivative="2"/></ScalarVariable>
    <ScalarVariable name="F" valueReference="3" causality="input" canHandleMultipleSetPerTimeInstant="false"><Real declaredType="Force" start="0" max="100"/></ScalarVariable>
    <ScalarVariable name="m" valueReference="4" causality="parameter" variability="fixed"><Real start="1" unit="kg" min="0"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="5" causality="parameter" variability="tunable"><Enumeration declaredType="Mode" start="1"/></ScalarVariable>
    <ScalarVariable name="n" valueReference="6" causality="output"><Integer declaredType="Count"/></ScalarVariable>
    <ScalarVariable name="exact" valueReference="7" causality="parameter" variability="fixed"><Boolean start="true"/></ScalarVariable>
    <ScalarVariable name="label" valueReference="8" causality="parameter" variability="fixed"><String start="a &amp; b"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="2"/><Unknown index="7" dependencies=""/></Outputs>
    <Derivatives><Unknown index="3" dependencies="2 4" dependenciesKind="dependent fixed"/></Derivatives>
    <InitialUnknowns><Unknown index="7"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"#;

fn parse(text: &str) -> Result<ModelDescription> {
    ModelDescription::from_xml(text)
}

#[test]
fn full_description_is_parsed_with_defaults() {
    let md = parse(FULL).unwrap();
    assert_eq!(md.model_name, "demo");
    assert_eq!(md.guid, "{1234}");
    assert_eq!(md.author.as_deref(), Some("me"));
    assert_eq!(
        md.variable_naming_convention,
        VariableNamingConvention::Structured
    );
    let cs = &md.co_simulation;
    assert_eq!(cs.model_identifier, "demo");
    assert!(
        cs.can_interpolate_inputs && cs.can_get_and_set_fmu_state && cs.can_serialize_fmu_state
    );
    assert!(!cs.needs_execution_tool && !cs.can_be_instantiated_only_once_per_process);
    assert_eq!(cs.max_output_derivative_order, 2);
    assert!(md.model_exchange.is_none());
    assert_eq!(md.unit_definitions[0].base_unit.unwrap().s, -2);
    assert_eq!(md.unit_definitions[1].base_unit.unwrap().offset, 273.15);
    assert_eq!(md.unit_definitions[1].display_units[0].factor, 1.8);
    assert_eq!(md.type_definitions.len(), 3);
    assert_eq!(md.log_categories[0].name, "logAll");
    assert_eq!(md.default_experiment.unwrap().step_size, Some(0.001));

    let x = md.variable("x").unwrap();
    assert_eq!(x.initial, Some(Initial::Exact));
    assert_eq!(x.variability, Variability::Continuous);
    let der = md.variable("der(x)").unwrap();
    assert_eq!(der.causality, Causality::Local);
    assert_eq!(der.initial, Some(Initial::Calculated));
    assert_eq!(der.real().unwrap().derivative, Some(2));
    let f = md.variable("F").unwrap();
    assert_eq!(f.initial, None);
    assert_eq!(f.can_handle_multiple_set_per_time_instant, Some(false));
    let fr = f.real().unwrap();
    assert_eq!(fr.attributes.unit.as_deref(), Some("N"));
    assert_eq!(fr.attributes.nominal, Some(10.0));
    assert_eq!(fr.attributes.max, Some(100.0));
    assert_eq!(
        md.variable("mode").unwrap().base_type(),
        BaseType::Enumeration
    );
    let n = md.variable("n").unwrap();
    assert_eq!(n.variability, Variability::Discrete);
    match &n.kind {
        VariableKind::Integer(i) => assert_eq!(i.attributes.min, Some(0)),
        other => panic!("{other:?}"),
    }
    match &md.variable("label").unwrap().kind {
        VariableKind::String(s) => assert_eq!(s.start.as_deref(), Some("a & b")),
        other => panic!("{other:?}"),
    }
    match &md.variable("exact").unwrap().kind {
        VariableKind::Boolean(b) => assert_eq!(b.start, Some(true)),
        other => panic!("{other:?}"),
    }
    let s = &md.model_structure;
    assert_eq!(s.outputs[0].dependencies, None);
    assert_eq!(s.outputs[1].dependencies, Some(vec![]));
    assert_eq!(s.derivatives[0].dependencies, Some(vec![2, 4]));
    assert_eq!(
        s.derivatives[0].dependencies_kind,
        Some(vec![DependencyKind::Dependent, DependencyKind::Fixed])
    );
    assert_eq!(s.initial_unknowns[0].index, 7);
    assert_eq!(md.variable_by_index(2).unwrap().name, "x");
}

#[test]
fn other_fmi_versions_are_refused_by_the_peek() {
    for (version, text) in [
        (
            "3.0",
            r#"<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="x"><Bogus"#,
        ),
        (
            "1.0",
            r#"<fmiModelDescription fmiVersion="1.0" modelName="m" guid="x"/>"#,
        ),
    ] {
        match parse(text) {
            Err(Error::UnsupportedFmiVersion { version: v, .. }) => assert_eq!(v, version),
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn model_exchange_only_is_refused() {
    let text = FULL.replace("<CoSimulation", "<ModelExchange");
    assert!(matches!(parse(&text), Err(Error::NotCoSimulation { .. })));
}

#[test]
fn semantic_errors_name_the_line() {
    let text = FULL.replace(
        r#"valueReference="4" causality="parameter" variability="fixed""#,
        r#"valueReference="4" causality="parameter""#,
    );
    match parse(&text) {
        Err(e @ Error::InvalidModelDescription { line: 25, .. }) => {
            assert!(e.to_string().contains("'m'"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    let text = FULL.replace(r#"<Real start="1"/>"#, r#"<Real start="one"/>"#);
    assert!(matches!(
        parse(&text),
        Err(Error::InvalidModelDescription { line: 22, .. })
    ));
    let text = FULL.replace(
        r#"index="7" dependencies="""#,
        r#"index="70" dependencies="""#,
    );
    assert!(matches!(
        parse(&text),
        Err(Error::InvalidModelDescription { .. })
    ));
}

#[test]
fn unknown_variable_suggests_close_names() {
    let md = parse(FULL).unwrap();
    match md.variable("xx") {
        Err(e @ Error::UnknownVariable { .. }) => {
            assert_eq!(
                e.to_string(),
                "no variable 'xx' in model 'demo'; did you mean 'x'?"
            )
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn duplicate_names_are_refused_at_the_second_definition() {
    let text = FULL.replace(
        r#"name="n" valueReference="6""#,
        r#"name="x" valueReference="6""#,
    );
    match parse(&text) {
        Err(e @ Error::InvalidModelDescription { line: 27, .. }) => {
            assert!(e.to_string().contains("duplicate variable name 'x'"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn truncated_and_mangled_documents_never_panic() {
    // Every prefix, and every single-byte corruption at a stride, yields Ok or Err.
    for end in (0..FULL.len()).filter(|&i| FULL.is_char_boundary(i)) {
        let _ = parse(&FULL[..end]);
    }
    let bytes = FULL.as_bytes();
    for i in (0..bytes.len()).step_by(7) {
        for replacement in [b'<', b'>', b'"', b'&', b'/', 0xFF] {
            let mut mangled = bytes.to_vec();
            mangled[i] = replacement;
            let _ = parse_bytes(&mangled, Path::new("m.xml"), Path::new("m.fmu"));
        }
    }
}

#[test]
fn a_deeply_nested_description_is_one_error() {
    // 200 000 levels (1.4 MB) inside an annotation: refused at the first element past
    // the limit, with the file and the position.
    let depth = 200_000;
    let deep = FULL.replace(
        "<ModelVariables>",
        &format!(
            "<VendorAnnotations><Tool name=\"t\">{}{}</Tool></VendorAnnotations>\n  <ModelVariables>",
            "<x>".repeat(depth),
            "</x>".repeat(depth)
        ),
    );
    let err = parse(&deep).unwrap_err();
    // The root, VendorAnnotations and Tool are three levels.
    let column = 3 + "<VendorAnnotations><Tool name=\"t\">".len() + 3 * (crate::xml::MAX_DEPTH - 3);
    assert!(
        matches!(err, Error::XmlLimit { line: 20, column: c, .. } if c == column),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        format!(
            "XML file 'modelDescription.xml' is over a limit at line 20, column {column}: \
             elements nested more than 256 deep (the limit)"
        )
    );
}
